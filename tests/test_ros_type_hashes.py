"""hil's ROS 2 type hashes, per distribution, against ROS's own: every interface hil's ROS
faces declare, hashed by rosidl_generator_type_description (ROS's implementation of
REP-2016) over the definitions that distribution releases. control_msgs ships no wheel:
its FollowJointTrajectory is written here as each release defines it and run through ROS's
pipeline (.action -> IDL -> type description); the other packages' hashes are the
type-description files ROS's message wheels were generated with."""

from __future__ import annotations

import contextlib
import io
import json
import sys
from pathlib import Path

import pytest
from rosidl_adapter.action import convert_action_to_idl
from rosidl_adapter.msg import convert_msg_to_idl
from rosidl_adapter.srv import convert_srv_to_idl
from rosidl_generator_type_description import generate_type_hash

from hil.messaging.ros.interfaces import DISTROS, FollowJointTrajectory, TypeHashes

#: where the message wheels put their generated type descriptions (share/<pkg>/<kind>/X.json)
SHARE = Path(sys.prefix) / "share"

# control_msgs, as its releases define the files FollowJointTrajectory needs (comments left out)
JOINT_TOLERANCE = "string name\nfloat64 position\nfloat64 velocity\nfloat64 acceleration\n"
JOINT_COMPONENT_TOLERANCE = (
    "uint16 X_AXIS=1\nuint16 Y_AXIS=2\nuint16 Z_AXIS=3\nuint16 TRANSLATION=4\n"
    "uint16 ROTATION=5\nstring joint_name\nuint16 component\nfloat64 position\n"
    "float64 velocity\nfloat64 acceleration\n")
GOAL = ("trajectory_msgs/JointTrajectory trajectory\n"
        "trajectory_msgs/MultiDOFJointTrajectory multi_dof_trajectory\n"
        "JointTolerance[] path_tolerance\nJointComponentTolerance[] component_path_tolerance\n"
        "JointTolerance[] goal_tolerance\nJointComponentTolerance[] component_goal_tolerance\n"
        "builtin_interfaces/Duration goal_time_tolerance\n")
RESULT = ("int32 error_code\nint32 SUCCESSFUL = 0\nint32 INVALID_GOAL = -1\n"
          "int32 INVALID_JOINTS = -2\nint32 OLD_HEADER_TIMESTAMP = -3\n"
          "int32 PATH_TOLERANCE_VIOLATED = -4\nint32 GOAL_TOLERANCE_VIOLATED = -5\n"
          "string error_string\n")
FEEDBACK_5 = ("std_msgs/Header header\nstring[] joint_names\n"
              "trajectory_msgs/JointTrajectoryPoint desired\n"
              "trajectory_msgs/JointTrajectoryPoint actual\n"
              "trajectory_msgs/JointTrajectoryPoint error\n"
              "string[] multi_dof_joint_names\n"
              "trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_desired\n"
              "trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_actual\n"
              "trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_error\n")
#: 6.3 adds "the currently used point" of each trajectory
FEEDBACK_6 = (FEEDBACK_5.replace("JointTrajectoryPoint error\n",
                                 "JointTrajectoryPoint error\nint32 index\n")
              + "int32 multi_dof_index\n")
#: the control_msgs each distribution releases: Jazzy 5.x, Kilted and Lyrical 6.x
CONTROL_MSGS_FEEDBACK = {"jazzy": FEEDBACK_5, "kilted": FEEDBACK_6, "lyrical": FEEDBACK_6}
#: the FollowJointTrajectory hash ROS computes for Kilted's feedback, as reported on issue 27
KILTED_FEEDBACK_MESSAGE_PREFIX = "RIHS01_95618cc7"

#: the other interfaces hil's ROS faces declare (RosControlFace, RosClockFace, the action,
#: every node's parameters, /rosout and type descriptions)
MESSAGES = ("sensor_msgs/msg/JointState", "sensor_msgs/msg/Imu",
            "geometry_msgs/msg/WrenchStamped",
            "diagnostic_msgs/msg/DiagnosticArray", "std_msgs/msg/String",
            "rosgraph_msgs/msg/Clock", "action_msgs/msg/GoalStatusArray",
            "rcl_interfaces/msg/Log", "rcl_interfaces/msg/ParameterEvent")
SERVICES = ("std_srvs/srv/Trigger", "action_msgs/srv/CancelGoal",
            *(f"rcl_interfaces/srv/{name}" for name in (
                "ListParameters", "GetParameters", "GetParameterTypes", "DescribeParameters",
                "SetParameters", "SetParametersAtomically")),
            "type_description_interfaces/srv/GetTypeDescription")


#: controller_manager_msgs as ros2_control's jazzy, kilted and master branches define them
#: (identical; comments left out)
CONTROLLER_MANAGER_MSGS = {
    "msg/ChainConnection.msg": "string name\nstring[] reference_interfaces\n",
    "msg/ControllerState.msg":
        "string name\nstring state\nstring type\nbool is_async\nuint16 update_rate\n"
        "string[] claimed_interfaces\nstring[] required_command_interfaces\n"
        "string[] required_state_interfaces\nbool is_chainable\nbool is_chained\n"
        "string[] exported_state_interfaces\nstring[] reference_interfaces\n"
        "ChainConnection[] chain_connections\n",
    "srv/ListControllers.srv": "---\ncontroller_manager_msgs/ControllerState[] controller\n",
    "srv/SwitchController.srv":
        "string[] activate_controllers\nstring[] deactivate_controllers\nint32 strictness\n"
        "int32 BEST_EFFORT=1\nint32 STRICT=2\nint32 AUTO=3\nint32 FORCE_AUTO=4\n"
        "bool activate_asap\nbuiltin_interfaces/Duration timeout\n---\nbool ok\n"
        "string message\n",
}


def control_msgs_hashes(feedback: str, folder: Path) -> dict[str, str]:
    """ROS's hashes of control_msgs' FollowJointTrajectory with this feedback definition,
    computed by rosidl's own pipeline against the message wheels' type descriptions."""
    return ros_hashes("control_msgs", {
        "msg/JointTolerance.msg": JOINT_TOLERANCE,
        "msg/JointComponentTolerance.msg": JOINT_COMPONENT_TOLERANCE,
        "action/FollowJointTrajectory.action": f"{GOAL}---\n{RESULT}---\n{feedback}"}, folder)


def ros_hashes(name: str, files: dict[str, str], folder: Path) -> dict[str, str]:
    """ROS's hashes of a package of these interface files (rosidl's own pipeline)."""
    package = folder / name
    idl = folder / "idl"
    converters = {".action": convert_action_to_idl, ".srv": convert_srv_to_idl,
                  ".msg": convert_msg_to_idl}
    for relative, text in files.items():
        source = package / relative
        source.parent.mkdir(parents=True, exist_ok=True)
        source.write_text(text)
        (idl / source.parent.name).mkdir(parents=True, exist_ok=True)
        with contextlib.redirect_stdout(io.StringIO()):        # it says what it reads
            converters[source.suffix](package, name, Path(relative), idl / source.parent.name)
    arguments = folder / "arguments.json"
    arguments.write_text(json.dumps({
        "package_name": name, "output_dir": str(folder / "out"),
        "idl_tuples": [f"{idl}:{path.relative_to(idl)}" for path in sorted(idl.rglob("*.idl"))],
        "include_paths": [f"{p.name}:{p}" for p in SHARE.iterdir() if p.is_dir()]}))
    hashes = {}
    for generated in generate_type_hash(str(arguments)):
        for entry in json.loads(Path(generated).read_text())["type_hashes"]:
            hashes[entry["type_name"]] = entry["hash_string"]
    return hashes


def wheel_hash(name: str) -> str:
    """The hash ROS's generated type description of ``name`` carries."""
    document = json.loads((SHARE / f"{name}.json").read_text())
    return document["type_hashes"][0]["hash_string"]


def test_the_message_wheels_type_descriptions_are_installed():
    missing = [name for name in MESSAGES + SERVICES if not (SHARE / f"{name}.json").is_file()]
    assert not missing, f"no generated type description under {SHARE} for {missing}"


@pytest.mark.parametrize("distro", sorted(DISTROS))
def test_every_interface_hil_declares_has_the_hash_ros_computes_for_that_distribution(
        distro, tmp_path):
    ours = TypeHashes(distro)
    action = FollowJointTrajectory.for_distro(ours)
    ros = control_msgs_hashes(CONTROL_MSGS_FEEDBACK[distro], tmp_path)
    base = "control_msgs/action/FollowJointTrajectory"
    pairs = {f"{base}_SendGoal": action.send_goal.type_hash,
             f"{base}_GetResult": action.get_result.type_hash,
             f"{base}_FeedbackMessage": action.feedback.type_hash}
    expected = {name: ros[name] for name in pairs}
    pairs |= {"action_msgs/srv/CancelGoal": action.cancel_goal.type_hash,
              "action_msgs/msg/GoalStatusArray": action.status.type_hash}
    pairs |= {name: ours.message(name).type_hash for name in MESSAGES}
    pairs |= {name: ours.service(name).type_hash for name in SERVICES}
    expected |= {name: wheel_hash(name) for name in pairs if name not in expected}
    assert pairs == expected


def test_controller_manager_services_and_commands_have_the_hashes_ros_computes(tmp_path):
    """The ROS face's controller_manager services (RosControllerManager) and the forward
    controllers' command topic."""
    ros = ros_hashes("controller_manager_msgs", CONTROLLER_MANAGER_MSGS, tmp_path)
    for distro in sorted(DISTROS):
        ours = TypeHashes(distro)
        for service in ("ListControllers", "SwitchController"):
            name = f"controller_manager_msgs/srv/{service}"
            assert ours.service(name).type_hash == ros[name], (distro, name)
        name = "std_msgs/msg/Float64MultiArray"
        assert ours.message(name).type_hash == wheel_hash(name), distro


def test_kilted_feedback_is_the_one_ros_reports_and_differs_from_jazzys(tmp_path):
    kilted = control_msgs_hashes(FEEDBACK_6, tmp_path)
    name = "control_msgs/action/FollowJointTrajectory_FeedbackMessage"
    assert kilted[name].startswith(KILTED_FEEDBACK_MESSAGE_PREFIX)
    jazzy = FollowJointTrajectory.for_distro(TypeHashes("jazzy")).feedback.type_hash
    assert jazzy != kilted[name]
