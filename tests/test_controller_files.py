"""A user's controller_manager YAML read as ros2_control (jazzy) reads it: the
controller_manager's list of controllers, the spawner's --param-file layout (a controller's
type in its own ros__parameters), ROS's parameter-file rules (rcl_yaml_param_parser, rclcpp's
parameter_map_from), and what hil refuses, naming file, line and key. Fixtures:
tests/controllers (Universal Robots' and ros2_control_demos' own files, unchanged)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hil.bus_config import load_bus_config
from hil.controllers import (
    GoalStatus, JointConstraint, JointTrajectoryController, TrajectoryGoal, TrajectoryPoint,
)
from hil.controllers.config import controllers_for
from hil.errors import HilError
from trajectory_follower import Follower

HERE = Path(__file__).parent
UR_BENCH = HERE / "controllers" / "ur3_with_ur_controllers.yaml"
JTC, POSITION, VELOCITY = ("joint_trajectory_controller", "forward_position_controller",
                           "forward_velocity_controller")


def test_universal_robots_controller_file_loads_unchanged_onto_the_ur3():
    controllers = controllers_for(load_bus_config(UR_BENCH))
    jtc = controllers.trajectory
    assert controllers.trajectory_name == JTC and controllers.active == (JTC,)
    assert jtc.joints == ("joint1", "joint2", "joint3", "joint4", "joint5", "joint6")
    assert jtc.command_interfaces == ("position",) and jtc.stopped_velocity_tolerance == 0.2
    assert jtc.goal_time == 0.0 and jtc.constraint("joint3").goal == 0.1
    assert jtc.constraint("joint3").trajectory == 0.2 and not jtc.allow_partial_joints_goal
    assert {f.name for f in controllers.forwards} == {POSITION, VELOCITY}
    warned = "\n".join(str(w) for w in controllers.warnings)
    assert "ur_controllers.yaml:24: warning: controller 'forward_effort_controller'" in warned
    assert "'state_publish_rate' is not a parameter" in warned
    assert "speed_scaling: state_interface" in warned


@pytest.mark.parametrize("text, words", [
    ("joint_trajectory_controller:\n  ros__parameters:\n    joints: [$(command ls)]\n",
     "controllers.yaml:7: error: launch substitution '$(command ls)'"),
    ("joint_trajectory_controller:\n  ros__parameters:\n    joints: [$(var prefix)joint1]\n",
     "controllers.yaml:7: error: $(var prefix): no value for 'prefix'"),
    ("joint_trajectory_controller:\n  ros__parameters:\n    joints: [shoulder]\n",
     "controllers.yaml:7: error: controller 'joint_trajectory_controller': joint 'shoulder' "
     "is not a driven joint"),
    ("joint_trajectory_controller:\n  ros__parameters:\n    joints: [joint1]\n"
     "    command_interfaces: [effort]\n",
     "controllers.yaml:8: error: controller 'joint_trajectory_controller': command_interfaces "
     "['effort']"),
    ("joint_trajectory_controller:\n  ros__parameters:\n    joints: [joint1]\n"
     "    constraints: {goal_time: -1}\n",
     "controllers.yaml:8: error: controller 'joint_trajectory_controller': constraints: "
     "goal_time must be >= 0"),
    ("    fwd:\n      type: position_controllers/JointGroupPositionController\n"
     "joint_trajectory_controller:\n  ros__parameters:\n    joints: [joint1]\n"
     "fwd:\n  ros__parameters:\n    joints: [joint1, joint1]\n",
     "controllers.yaml:12: error: controller 'fwd': a joint is named twice in 'joints'"),
], ids=["command substitution", "var without a value", "unknown joint", "effort commands",
        "negative goal_time", "forward controller's joint twice"])
def test_a_controller_file_hil_cannot_honour_is_refused_naming_the_line(tmp_path, text, words):
    manager = ("controller_manager:\n  ros__parameters:\n    joint_trajectory_controller:\n"
               "      type: joint_trajectory_controller/JointTrajectoryController\n")
    refused = _refusal(tmp_path, manager + text)
    expected = words.replace("controllers.yaml:", f"{tmp_path / 'controllers.yaml'}:")
    assert expected in refused, refused


def test_an_update_rate_that_is_no_number_is_one_error_and_no_made_up_rate(tmp_path):
    refused = _refusal(tmp_path, "controller_manager:\n  ros__parameters:\n"
                                 "    update_rate: fast\n")
    assert "'update_rate' must be a number, not 'fast'" in refused
    assert "update_rate 1 Hz" not in refused, refused


def _refusal(tmp_path, text: str) -> str:
    """What hil says of a controllers file ``text`` on the ur3 fixture's bench (HilError)."""
    (tmp_path / "controllers.yaml").write_text(text)
    with pytest.raises(HilError) as caught:
        controllers_for(load_bus_config(_bench(tmp_path)))
    return str(caught.value)


def _bench(tmp_path) -> Path:
    """The ur3 fixture's bench, running ``tmp_path``'s controllers.yaml."""
    bench = (HERE / "fixtures" / "ur3_virtual.yaml").read_text().replace(
        "../../robots", str(HERE.parent / "robots"))
    (tmp_path / "bench.yaml").write_text(bench + "controllers: {file: controllers.yaml}\n")
    return tmp_path / "bench.yaml"


# --- the spawner's --param-file layout (ros2_control jazzy) -----------------------------------

RRBOT_JTC = HERE / "controllers" / "rrbot_jtc.yaml"
MANAGER = ("controller_manager:\n  ros__parameters:\n    joint_trajectory_controller:\n"
           "      type: joint_trajectory_controller/JointTrajectoryController\n")


def _loaded(tmp_path, text: str):
    """What hil loads of a controllers file ``text`` on the ur3 fixture's bench."""
    (tmp_path / "controllers.yaml").write_text(text)
    return controllers_for(load_bus_config(_bench(tmp_path)))


def test_a_ros2_control_demos_controller_file_is_read_as_the_spawner_reads_it(tmp_path):
    """ros2_control_demos (jazzy) example_1's rrbot_jtc.yaml, unchanged: a controller's type
    in its own ros__parameters, no controller_manager section, as `spawner
    joint_trajectory_position_controller --param-file rrbot_jtc.yaml` takes it
    (controller_manager_services.py: set_controller_parameters_from_param_files). Every
    value it sets is honoured, allow_integration_in_goal_trajectories: true included."""
    loaded = _loaded(tmp_path, RRBOT_JTC.read_text())
    jtc = loaded.trajectory
    assert loaded.trajectory_name == "joint_trajectory_position_controller"
    assert loaded.active == ("joint_trajectory_position_controller",) and not loaded.forwards
    assert jtc.joints == ("joint1", "joint2") and jtc.command_interfaces == ("position",)
    assert jtc.state_interfaces == ("position",) and jtc.interpolate_from_desired_state
    assert jtc.allow_integration_in_goal_trajectories and not loaded.warnings


def test_rrbot_jtc_yaml_moves_a_goal_of_velocities_by_their_integral(tmp_path):
    """rrbot_jtc.yaml's JTC takes a goal whose points give velocities alone and integrates
    their positions from the state before the trajectory (here at rest at 0) by the trapezoid
    rule (ros2_controllers jazzy trajectory.cpp, deduce_from_derivatives; test_trajectory.cpp,
    sample_trajectory_velocity_with_interpolation): v at 1 s and 2 s, 0 at 3 s passes
    p(1) = (0 + v) / 2 * 1 = v / 2, p(2) = p(1) + (v + v) / 2 * 1 = 1.5 v and ends at
    p(3) = p(2) + (v + 0) / 2 * 1 = 2 v."""
    (tmp_path / "controllers.yaml").write_text(RRBOT_JTC.read_text())
    config = load_bus_config(_bench(tmp_path))
    loaded = controllers_for(config)
    jtc = JointTrajectoryController(config.robot, loaded.trajectory, loaded.trajectory_name)
    follower = Follower(jtc)
    follower.run(0.01)
    v = np.array([0.2, -0.1])
    jtc.submit("g", TrajectoryGoal(("joint1", "joint2"), (
        TrajectoryPoint(1.0, (), tuple(v)), TrajectoryPoint(2.0, (), tuple(v)),
        TrajectoryPoint(3.0, (), (0.0, 0.0)))))
    follower.run(1.0)
    assert jtc.state().desired_positions == pytest.approx(v / 2)
    follower.run(1.0)
    assert jtc.state().desired_positions == pytest.approx(1.5 * v)
    (done,) = follower.run(1.02)
    assert done[1].status is GoalStatus.SUCCEEDED
    assert follower.q == pytest.approx(2 * v)


def test_a_bare_wildcard_section_gives_every_controller_its_parameters(tmp_path):
    """controller_manager's userdoc.rst (jazzy, spawner): a `/**:` section's parameters go to
    every node, each controller's own section adds its joints (rclcpp parameter_map_from:
    every entry whose name matches, in the file's order, a later value replacing an earlier).
    hil runs one JTC: the second is a warning."""
    loaded = _loaded(tmp_path, "/**:\n  ros__parameters:\n"
                     "    type: joint_trajectory_controller/JointTrajectoryController\n"
                     "    command_interfaces:\n      - position\n"
                     "    state_interfaces: [position]\n"
                     "    constraints: {goal_time: 0.5, joint1: {goal: 0.1}}\n"
                     "position_trajectory_controller_joint1:\n  ros__parameters:\n"
                     "    joints:\n      - joint1\n"
                     "    constraints: {joint1: {trajectory: 0.2}}\n"
                     "position_trajectory_controller_joint2:\n  ros__parameters:\n"
                     "    joints:\n      - joint2\n")
    jtc = loaded.trajectory
    assert loaded.trajectory_name == "position_trajectory_controller_joint1"
    assert jtc.joints == ("joint1",) and jtc.command_interfaces == ("position",)
    assert jtc.goal_time == 0.5 and jtc.constraint("joint1") == JointConstraint(0.2, 0.1)
    warned = "\n".join(str(w) for w in loaded.warnings)
    assert "'position_trajectory_controller_joint2': hil runs one joint trajectory " \
           "controller" in warned, warned


def test_a_controllers_own_type_and_the_managers_list_load_together(tmp_path):
    """The layouts mix: controller_manager lists some controllers, others carry their own
    type (ros2_control_demos example_3's rrbot_multi_interface_forward_controllers.yaml)."""
    loaded = _loaded(tmp_path, MANAGER + "joint_trajectory_controller:\n  ros__parameters:\n"
                     "    joints: [joint1]\n    command_interfaces: [position]\n"
                     "    state_interfaces: [position]\n"
                     "fwd:\n  ros__parameters:\n"
                     "    type: forward_command_controller/ForwardCommandController\n"
                     "    joints: [joint2]\n    interface_name: velocity\n")
    assert [(f.name, f.joints, f.interface) for f in loaded.forwards] == [
        ("fwd", ("joint2",), "velocity")]


@pytest.mark.parametrize("text, words", [
    ("joint_trajectory_controller:\n  type: x\n",
     "controllers.yaml:6: error: 'joint_trajectory_controller': 'type' lies outside any "
     "ros__parameters"),
    ("/**:\n  ros__parameters:\n    command_interfaces: [position]\n",
     "controllers.yaml:3: error: controller 'joint_trajectory_controller': 'joints' must be"),
    ("joint_trajectory_controller:\n  ros__parameters:\n    joints: [joint1]\n"
     "    constraints: {joint1: 0.1}\n",
     "controllers.yaml:8: error: controller 'joint_trajectory_controller': constraints: "
     "joint1 must be a mapping"),
    ("joint_trajectory_controller:\n  ros__parameters:\n    joints: [joint1]\n"
     "    command_interfaces: [position]\n    state_interfaces: [position, position]\n",
     "controllers.yaml:9: error: controller 'joint_trajectory_controller': state_interfaces "
     "['position', 'position']"),
], ids=["a value outside ros__parameters", "a wildcard without the joints",
        "a joint's constraints that are no mapping", "a state interface twice"])
def test_a_file_ros_refuses_is_refused_naming_the_key(tmp_path, text, words):
    """rcl_yaml_param_parser refuses a value that is not under a node's ros__parameters
    ("Cannot have a value before ros__parameters"); the spawner, a controller section without
    ros__parameters ("is not a valid ROS parameter file for controller node"); the JTC, a
    controller without joints, a joint's constraints that are no mapping, a state interface
    named twice (joint_trajectory_controller_parameters.yaml: size_gt<>, unique<>)."""
    refused = _refusal(tmp_path, MANAGER + text)
    assert words.replace("controllers.yaml:", f"{tmp_path / 'controllers.yaml'}:") in refused, \
        refused


def test_a_file_of_no_controller_says_where_hil_looked(tmp_path):
    refused = _refusal(tmp_path, "robot_state_publisher:\n  ros__parameters:\n"
                                 "    publish_frequency: 10.0\n")
    assert "no controllers: no controller_manager: ros__parameters: <name>: {type: ...} and " \
           "no controller's own <name>: ros__parameters: {type: ...}" in refused, refused


@pytest.mark.parametrize("key, line", [("command_interfaces", 8), ("state_interfaces", 8),
                                       ("command_joints", 8), ("joints", 7)])
def test_a_list_parameter_that_is_no_list_is_an_error_naming_file_and_key(tmp_path, key, line):
    """The JTC declares joints, command_joints, command_interfaces and state_interfaces as
    string_array (joint_trajectory_controller_parameters.yaml): `command_interfaces: 5` is
    an error naming file, line and key, never a traceback."""
    text = ("joint_trajectory_controller:\n  ros__parameters:\n    joints: [joint1]\n"
            f"    {key}: 5\n").replace("    joints: [joint1]\n    joints: 5", "    joints: 5")
    refused = _refusal(tmp_path, MANAGER + text)
    assert (f"{tmp_path / 'controllers.yaml'}:{line}: error: controller "
            f"'joint_trajectory_controller': '{key}' must be a ") in refused, refused


def test_a_controllers_own_type_wins_and_an_untyped_section_is_not_loaded(tmp_path):
    """The spawner sets `<name>.type` on controller_manager from the controller's own
    section (controller_manager_services.py, set_controller_parameters_from_param_files),
    so that type replaces the manager's; a section neither gives a type is no controller."""
    loaded = _loaded(tmp_path, MANAGER + "    fwd: {type: velocity_controllers/"
                     "JointGroupVelocityController}\n"
                     "joint_trajectory_controller:\n  ros__parameters:\n"
                     "    joints: [joint1]\n    command_interfaces: [position]\n"
                     "    state_interfaces: [position]\n"
                     "fwd:\n  ros__parameters:\n"
                     "    type: position_controllers/JointGroupPositionController\n"
                     "    joints: [joint2]\n"
                     "robot_state_publisher:\n  ros__parameters: {publish_frequency: 10.0}\n")
    assert [(f.name, f.interface) for f in loaded.forwards] == [("fwd", "position")]
    warned = "\n".join(str(w) for w in loaded.warnings)
    assert "controllers.yaml:13: warning: controller 'fwd': its own type " \
           "position_controllers/JointGroupPositionController replaces controller_manager's " \
           "velocity_controllers/JointGroupVelocityController" in warned, warned
    assert "controllers.yaml:15: warning: 'robot_state_publisher': controller_manager does " \
           "not list it" in warned, warned


def test_a_list_of_controllers_files_is_refused_saying_how_to_make_one(tmp_path):
    """jazzy's spawner takes several --param-file (spawner.py: `action="append"`; the
    controller loads them in order); the bus config's `controllers: file:` names one
    file: a list is an error naming the line, with how to make one file of them."""
    (tmp_path / "controllers.yaml").write_text(RRBOT_JTC.read_text())
    bench = _bench(tmp_path).read_text().replace(
        "controllers: {file: controllers.yaml}", "controllers: {file: [controllers.yaml]}")
    (tmp_path / "bench.yaml").write_text(bench)
    with pytest.raises(HilError) as caught:
        load_bus_config(tmp_path / "bench.yaml")
    assert "controllers: 'file' names one controllers file, not a list" in str(caught.value)
    assert "--param-file order" in str(caught.value)
