"""ROS 2 message layouts, encoded as CDR with ``rosbags`` (a maintained, pure-Python codec).

Payloads on Zenoh are the CDR encoding ROS 2 uses on the wire (little-endian
header ``00 01 00 00``), so a ROS 2 bridge maps keys, not bytes. Types that
rosbags does not ship (control_msgs' FollowJointTrajectory, action_msgs'
CancelGoal service) are registered from their .msg/.action field layouts;
hil's own types are ``hil_msgs/GoalResult`` (a goal's terminal status),
``hil_msgs/ControlSamples`` (a batch of control cycles, for recording and
plotting), ``hil_msgs/SimClock`` (the plant's time against the wall clock) and
``hil_msgs/SceneState`` (the scene's moving objects, contacts and floating base).
"""

from __future__ import annotations

import math
import struct

import numpy as np
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from hil.controllers import (
    GoalResult, GoalStatus, JointTolerance, TrajectoryGoal, TrajectoryPoint, TrajectoryPoints,
)

DEFINITIONS = {
    "control_msgs/msg/JointTolerance":
        "string name\nfloat64 position\nfloat64 velocity\nfloat64 acceleration",
    "control_msgs/msg/JointComponentTolerance":
        "string joint_name\nuint16 component\nfloat64 position\nfloat64 velocity\n"
        "float64 acceleration",
    "control_msgs/action/FollowJointTrajectory_Goal":
        "trajectory_msgs/JointTrajectory trajectory\n"
        "trajectory_msgs/MultiDOFJointTrajectory multi_dof_trajectory\n"
        "control_msgs/JointTolerance[] path_tolerance\n"
        "control_msgs/JointComponentTolerance[] component_path_tolerance\n"
        "control_msgs/JointTolerance[] goal_tolerance\n"
        "control_msgs/JointComponentTolerance[] component_goal_tolerance\n"
        "builtin_interfaces/Duration goal_time_tolerance",
    "control_msgs/action/FollowJointTrajectory_Result":
        "int32 error_code\nstring error_string",
    "control_msgs/action/FollowJointTrajectory_Feedback":
        "std_msgs/Header header\nstring[] joint_names\n"
        "trajectory_msgs/JointTrajectoryPoint desired\n"
        "trajectory_msgs/JointTrajectoryPoint actual\n"
        "trajectory_msgs/JointTrajectoryPoint error\nstring[] multi_dof_joint_names\n"
        "trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_desired\n"
        "trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_actual\n"
        "trajectory_msgs/MultiDOFJointTrajectoryPoint multi_dof_error",
    "control_msgs/action/FollowJointTrajectory_SendGoal_Request":
        "unique_identifier_msgs/UUID goal_id\n"
        "control_msgs/action/FollowJointTrajectory_Goal goal",
    "control_msgs/action/FollowJointTrajectory_SendGoal_Response":
        "bool accepted\nbuiltin_interfaces/Time stamp",
    "control_msgs/action/FollowJointTrajectory_FeedbackMessage":
        "unique_identifier_msgs/UUID goal_id\n"
        "control_msgs/action/FollowJointTrajectory_Feedback feedback",
    "control_msgs/action/FollowJointTrajectory_GetResult_Request":
        "unique_identifier_msgs/UUID goal_id",
    "control_msgs/action/FollowJointTrajectory_GetResult_Response":
        "int8 status\ncontrol_msgs/action/FollowJointTrajectory_Result result",
    "action_msgs/srv/CancelGoal_Request": "action_msgs/GoalInfo goal_info",
    "action_msgs/srv/CancelGoal_Response":
        "int8 return_code\naction_msgs/GoalInfo[] goals_canceling",
    "hil_msgs/msg/GoalResult":
        "unique_identifier_msgs/UUID goal_id\nint8 status\n"
        "control_msgs/action/FollowJointTrajectory_Result result",
    # arrays marked (cycles x N) are row-major, one row per control cycle, oldest first
    "hil_msgs/msg/ControlSamples":
        "uint64 first_cycle\nfloat64 period\nfloat64[] wall_time\nfloat64[] control_time\n"
        "string[] joint_names\nfloat64[] reference\nfloat64[] reference_velocity\n"
        "float64[] position\nfloat64[] velocity\nfloat64[] effort\n"
        "string[] actuator_names\nfloat64[] motor_torque\nuint8[] drive_state\n"
        "string[] state_names\nfloat64[] cycle_period\nfloat64[] round_trip",
    "hil_msgs/msg/SimClock": "float64 wall_time\nfloat64 sim_time",
    # the plant's scene now: each moving object's pose (names x 3, names x 4: w x y z), each
    # contact's point and force on its first body (contacts x 3 each), and a floating base's
    # pose (3 and 4; none for a fixed one), world frame
    "hil_msgs/msg/SceneState":
        "float64 wall_time\nfloat64 sim_time\nstring[] names\nfloat64[] position\n"
        "float64[] orientation\nfloat64[] contact_point\nfloat64[] contact_force\n"
        "float64[] base_position\nfloat64[] base_orientation",
    # a real-time process' stall (hil.realtime.stalls.Stall): at in s since the epoch
    "hil_msgs/msg/Stall": "string process\nfloat64 at\nfloat64 length\nfloat64 steal\n"
                          "string where",
    "std_srvs/srv/Trigger_Response": "bool success\nstring message",
    # controller_manager_msgs as ros2_control's jazzy branch releases them
    "controller_manager_msgs/msg/ChainConnection": "string name\nstring[] reference_interfaces",
    "controller_manager_msgs/msg/ControllerState":
        "string name\nstring state\nstring type\nbool is_async\nuint16 update_rate\n"
        "string[] claimed_interfaces\nstring[] required_command_interfaces\n"
        "string[] required_state_interfaces\nbool is_chainable\nbool is_chained\n"
        "string[] exported_state_interfaces\nstring[] reference_interfaces\n"
        "controller_manager_msgs/ChainConnection[] chain_connections",
    "controller_manager_msgs/srv/ListControllers_Response":
        "controller_manager_msgs/ControllerState[] controller",
    "controller_manager_msgs/srv/SwitchController_Request":
        "string[] activate_controllers\nstring[] deactivate_controllers\nint32 strictness\n"
        "bool activate_asap\nbuiltin_interfaces/Duration timeout",
    "controller_manager_msgs/srv/SwitchController_Response": "bool ok\nstring message",
}

TYPES = get_typestore(Stores.ROS2_HUMBLE)
for _name, _text in DEFINITIONS.items():
    TYPES.register(get_types_from_msg(_text, _name))

JOINT_STATE = "sensor_msgs/msg/JointState"
IMU = "sensor_msgs/msg/Imu"
WRENCH_STAMPED = "geometry_msgs/msg/WrenchStamped"
SEND_GOAL_REQUEST = "control_msgs/action/FollowJointTrajectory_SendGoal_Request"
SEND_GOAL_RESPONSE = "control_msgs/action/FollowJointTrajectory_SendGoal_Response"
FEEDBACK_MESSAGE = "control_msgs/action/FollowJointTrajectory_FeedbackMessage"
GET_RESULT_REQUEST = "control_msgs/action/FollowJointTrajectory_GetResult_Request"
GET_RESULT_RESPONSE = "control_msgs/action/FollowJointTrajectory_GetResult_Response"
CANCEL_REQUEST = "action_msgs/srv/msg/CancelGoal_Request"   # rosbags files srv parts so
CANCEL_RESPONSE = "action_msgs/srv/msg/CancelGoal_Response"
GOAL_RESULT = "hil_msgs/msg/GoalResult"
CONTROL_SAMPLES = "hil_msgs/msg/ControlSamples"
TRIGGER_RESPONSE = "std_srvs/srv/msg/Trigger_Response"
SIM_CLOCK = "hil_msgs/msg/SimClock"
SCENE_STATE = "hil_msgs/msg/SceneState"
STALL = "hil_msgs/msg/Stall"
LIST_CONTROLLERS_RESPONSE = "controller_manager_msgs/srv/msg/ListControllers_Response"
SWITCH_CONTROLLER_REQUEST = "controller_manager_msgs/srv/msg/SwitchController_Request"
SWITCH_CONTROLLER_RESPONSE = "controller_manager_msgs/srv/msg/SwitchController_Response"
CONTROLLER_STATE = "controller_manager_msgs/msg/ControllerState"
FLOAT64_MULTI_ARRAY = "std_msgs/msg/Float64MultiArray"
#: the CDR of a request without fields (std_srvs/Trigger's): the encapsulation header and
#: the one byte rosidl gives an empty structure
EMPTY_REQUEST = b"\x00\x01\x00\x00\x00"
DIAGNOSTIC_ARRAY = "diagnostic_msgs/msg/DiagnosticArray"
DIAGNOSTIC_STATUS = "diagnostic_msgs/msg/DiagnosticStatus"


def msg(typename: str, **fields):
    return TYPES.types[typename](**fields)


def encode(message, types=TYPES) -> bytes:
    """CDR of ``message`` as ``types`` (a rosbags store: hil's own, or a ROS distribution's,
    :func:`hil.messaging.ros.interfaces.distro_types`) lays out its type."""
    return bytes(types.serialize_cdr(message, message.__msgtype__))


def decode(data: bytes, typename: str, types=TYPES):
    """Decode CDR; raises ValueError (with the type) for anything malformed."""
    try:
        return types.deserialize_cdr(bytes(data), typename)
    except Exception as exc:   # rosbags raises struct/index/assertion errors on bad input
        raise ValueError(f"malformed {typename} payload ({len(data)} bytes): {exc}") from None


# --- small builders -----------------------------------------------------------

def time_cdr(seconds: float) -> bytes:
    """A builtin_interfaces/Time (or rosgraph_msgs/Clock, the same layout) as CDR, packed
    directly: a clock published every few ms from a real-time process costs a struct.pack,
    not a rosbags message (tests/test_ros_face.py decodes it with rosbags)."""
    return _TIME_CDR.pack(b"\x00\x01\x00\x00", *seconds_and_nanoseconds(seconds))


_TIME_CDR = struct.Struct("<4siI")


class JointStateCdr:
    """sensor_msgs/JointState of fixed joint names as CDR, packed by one struct: the joint
    states published every few cycles of a real-time loop cost a struct.pack, not a rosbags
    message and its serialiser (docs/performance.md, "2026-11-28, later: the second step,
    and where the rest goes (issue 48)"; tests/test_cdr.py holds the bytes against rosbags'
    own)."""

    def __init__(self, names):
        names = list(names)
        self._count = count = len(names)
        # XCDR1, little endian; alignment counts from the end of the encapsulation header.
        # header: stamp (int32, uint32) at 0, frame_id "" (length 1, NUL) at 8
        static, offset = bytearray(), 13
        for part in [struct.pack("<I", count)] + [
                struct.pack("<I", len(name.encode()) + 1) + name.encode() + b"\0"
                for name in names]:
            static += b"\0" * (-offset % 4) + part          # uint32s align to 4
            offset = 13 + len(static)
        layout = [f"<4siI5s{len(static)}s"]
        self._static = b"\x01\0\0\0\0", bytes(static)
        for _ in range(3):                      # position, velocity, effort: sequence<double>
            count_pad = -offset % 4
            offset += count_pad + 4
            data_pad = -offset % 8 if count else 0
            layout.append(f"{count_pad}xI{data_pad}x{count}d")
            offset += data_pad + 8 * count
        self._struct = struct.Struct("".join(layout))

    def encode(self, stamp: float, positions, velocities, efforts) -> bytes:
        """The message stamped ``stamp`` (s), one value per name in each array (ValueError
        otherwise, as for a stamp ROS cannot carry)."""
        n = self._count
        if not len(positions) == len(velocities) == len(efforts) == n:
            raise ValueError(f"{n} joints, values for {len(positions)}, {len(velocities)}, "
                             f"{len(efforts)}")
        # as Python floats: struct packs them faster than numpy's scalars
        # (docs/performance.md, "2026-12-06, later: figures from code comments")
        return self._struct.pack(b"\x00\x01\x00\x00", *seconds_and_nanoseconds(stamp),
                                 *self._static, n, *_floats(positions), n, *_floats(velocities),
                                 n, *_floats(efforts))


class ImuCdr:
    """sensor_msgs/Imu of one sensor as CDR, packed by one struct (as :class:`JointStateCdr`,
    for the same reason: a sample every few cycles of a real-time loop; tests/test_cdr.py
    holds the bytes against rosbags' own). A field the sample lacks gets covariance element
    0 at -1, as sensor_msgs/Imu says; the others their diagonal from ``variances``."""

    def __init__(self, frame_id: str, variances: tuple[float, float, float]):
        """``variances``: of the orientation (rad²), angular velocity ((rad/s)²) and linear
        acceleration ((m/s²)²) of each axis (0: unknown)."""
        self._struct, self._name = _stamped_doubles(frame_id, 37)
        self._covariances = [[v, 0.0, 0.0, 0.0, v, 0.0, 0.0, 0.0, v] for v in variances]

    def encode(self, stamp: float, orientation, angular_velocity, linear_acceleration) -> bytes:
        """The message stamped ``stamp`` (s): ``orientation`` (w, x, y, z), angular velocity
        (rad/s) and linear acceleration (m/s²) as sequences of floats, each None if absent."""
        values: list[float] = []
        for field, size, covariance in zip((orientation, angular_velocity,
                                            linear_acceleration), (4, 3, 3), self._covariances):
            if field is None:
                values += [0.0] * size + [-1.0] + [0.0] * 8
                continue
            field = [float(v) for v in field]
            values += field[1:] + field[:1] if size == 4 else field     # x, y, z, w
            values += covariance
        return self._struct.pack(b"\x00\x01\x00\x00", *seconds_and_nanoseconds(stamp),
                                 len(self._name), self._name, *values)


class WrenchCdr:
    """geometry_msgs/WrenchStamped of one sensor as CDR, packed by one struct (as
    :class:`ImuCdr`; tests/test_cdr.py holds the bytes against rosbags' own)."""

    def __init__(self, frame_id: str):
        self._struct, self._name = _stamped_doubles(frame_id, 6)

    def encode(self, stamp: float, force, torque) -> bytes:
        """The message stamped ``stamp`` (s): force (N) and torque (N·m), three floats each."""
        return self._struct.pack(b"\x00\x01\x00\x00", *seconds_and_nanoseconds(stamp),
                                 len(self._name), self._name, *map(float, force),
                                 *map(float, torque))


def _stamped_doubles(frame_id: str, count: int) -> tuple[struct.Struct, bytes]:
    """The struct of a message that is a std_msgs/Header of ``frame_id`` then ``count``
    float64s (XCDR1, little endian, after the encapsulation header), and the frame id as it
    packs (NUL-terminated)."""
    name = frame_id.encode() + b"\0"
    pad = -(12 + len(name)) % 8          # float64s align to 8 after the header
    return struct.Struct(f"<4siII{len(name)}s{pad}x{count}d"), name


def _floats(values) -> list[float]:
    return np.asarray(values, dtype=np.float64).tolist()


def time_msg(seconds: float):
    sec, nanosec = seconds_and_nanoseconds(seconds)
    return msg("builtin_interfaces/msg/Time", sec=sec, nanosec=nanosec)


def duration_msg(seconds: float):
    sec, nanosec = seconds_and_nanoseconds(seconds)
    return msg("builtin_interfaces/msg/Duration", sec=sec, nanosec=nanosec)


def seconds_and_nanoseconds(seconds: float) -> tuple[int, int]:
    """builtin_interfaces' (int32 sec, uint32 nanosec); ValueError for what they cannot hold."""
    if not math.isfinite(seconds) or not -2**31 <= seconds < 2**31:
        raise ValueError(f"{seconds} s is not a time ROS 2 can carry (finite, |t| < 2^31 s)")
    sec = int(seconds // 1)
    nanosec = int(round((seconds - sec) * 1e9))
    if nanosec == 1_000_000_000:
        sec, nanosec = sec + 1, 0
    return sec, nanosec


def seconds_of(stamp) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


def uuid_msg(goal_id: str):
    raw = bytes.fromhex(goal_id)
    return msg("unique_identifier_msgs/msg/UUID", uuid=np.frombuffer(raw, dtype=np.uint8).copy())


def goal_id_of(uuid) -> str:
    return bytes(uuid.uuid).hex()


def header(seconds: float, frame: str = ""):
    return msg("std_msgs/msg/Header", stamp=time_msg(seconds), frame_id=frame)


def point_msg(positions=(), velocities=(), accelerations=(), time_from_start: float = 0.0):
    array = lambda values: np.asarray(values, dtype=np.float64)   # noqa: E731
    return msg("trajectory_msgs/msg/JointTrajectoryPoint", positions=array(positions),
               velocities=array(velocities), accelerations=array(accelerations),
               effort=array(()), time_from_start=duration_msg(time_from_start))


def joint_state_msg(stamp: float, names, positions, velocities, efforts):
    return msg(JOINT_STATE, header=header(stamp), name=list(names),
               position=np.asarray(positions, dtype=np.float64),
               velocity=np.asarray(velocities, dtype=np.float64),
               effort=np.asarray(efforts, dtype=np.float64))


# --- goals ----------------------------------------------------------------------

def goal_msg(goal: TrajectoryGoal, stamp: float = 0.0):
    """A FollowJointTrajectory goal; ``stamp`` 0 means "start now"."""
    tolerances = lambda items: [msg("control_msgs/msg/JointTolerance", name=t.name,  # noqa: E731
                                    position=t.position, velocity=t.velocity, acceleration=0.0)
                                for t in items]
    trajectory = msg("trajectory_msgs/msg/JointTrajectory", header=header(stamp),
                     joint_names=list(goal.joint_names),
                     points=[point_msg(p.positions, p.velocities, p.accelerations,
                                       p.time_from_start) for p in goal.points])
    multi = msg("trajectory_msgs/msg/MultiDOFJointTrajectory", header=header(0.0),
                joint_names=[], points=[])
    return msg("control_msgs/action/FollowJointTrajectory_Goal", trajectory=trajectory,
               multi_dof_trajectory=multi, path_tolerance=tolerances(goal.path_tolerance),
               component_path_tolerance=[], goal_tolerance=tolerances(goal.goal_tolerance),
               component_goal_tolerance=[],
               goal_time_tolerance=duration_msg(goal.goal_time_tolerance))


def goal_from_msg(goal, start_time: float | None) -> TrajectoryGoal:
    """The controller's goal; ``start_time`` is the header stamp on its clock (None = now)."""
    trajectory = goal.trajectory
    if len(goal.multi_dof_trajectory.joint_names):
        raise ValueError("multi-DOF trajectories are not supported")
    points = _points_from_msgs(trajectory.points, len(trajectory.joint_names))
    tolerance = lambda items: tuple(JointTolerance(t.name, t.position, t.velocity)  # noqa: E731
                                    for t in items)
    return TrajectoryGoal(tuple(trajectory.joint_names), points, start_time,
                          tolerance(goal.path_tolerance), tolerance(goal.goal_tolerance),
                          seconds_of(goal.goal_time_tolerance),
                          has_efforts=any(len(p.effort) for p in trajectory.points))


def _points_from_msgs(points, joints: int):
    """JointTrajectoryPoint messages as TrajectoryPoints (arrays) where every point has the
    same fields; otherwise point by point, so the controller names the odd one."""
    times = np.array([seconds_of(p.time_from_start) for p in points], dtype=float)
    arrays = []
    for what in ("positions", "velocities", "accelerations"):
        lengths = {len(getattr(p, what)) for p in points}
        if lengths == {0} and what != "positions":
            arrays.append(None)
        elif lengths == {joints}:
            arrays.append(np.array([getattr(p, what) for p in points], dtype=float))
        else:
            return tuple(TrajectoryPoint(float(t), tuple(p.positions.tolist()),
                                         tuple(p.velocities.tolist()),
                                         tuple(p.accelerations.tolist()))
                         for t, p in zip(times, points))
    return TrajectoryPoints(times, *arrays)


def result_msg(goal_id: str, result: GoalResult):
    return msg(GOAL_RESULT, goal_id=uuid_msg(goal_id), status=result.status.value,
               result=msg("control_msgs/action/FollowJointTrajectory_Result",
                          error_code=result.error_code, error_string=result.error_string))


def result_from_msg(message) -> GoalResult:
    return GoalResult(GoalStatus(message.status), message.result.error_code,
                      message.result.error_string)
