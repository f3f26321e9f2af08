"""hil's controller and simulator as ROS 2 nodes on rmw_zenoh.

The controller's node (``hil_control``) serves what ros2_control serves, by the names
MoveIt and rqt look for: ``joint_states`` (sensor_msgs/JointState), the
FollowJointTrajectory action at ``joint_trajectory_controller/follow_joint_trajectory``,
``diagnostics`` (diagnostic_msgs/DiagnosticArray) and ``robot_description``
(std_msgs/String, transient local). The simulator's node (``hil_sim``) publishes
``/clock`` (rosgraph_msgs/Clock) from the plant's time.

Both are adapters: the payloads are the CDR bytes hil already encodes for its own keys,
put again with rmw_zenoh's attachment on the ROS key expressions.
"""

from __future__ import annotations

import math
import os
import struct
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import zenoh

from hil.controllers import ControllerState
from hil.errors import HilError
from hil.messaging import cdr
from hil.controllers.manager import ControllerManager
from hil.messaging.action import encode_feedback_once, feedback_message
from hil.messaging.ros.controller_manager import RosControllerManager
from hil.messaging.diagnostics import DiagnosticStatus
from hil.messaging.face import ControlFace
from hil.messaging.keys import IMU, WRENCH, direct, key
from hil.messaging.ros.action import RosTrajectoryActionServer
from hil.messaging.ros.interfaces import (
    DEFAULT_DISTRO, DISTRO_DEFINITIONS, FEEDBACK, FollowJointTrajectory, TypeHashes, distro_types,
    known_distro,
)
from hil.messaging.ros.node import RosContext, RosNode, RosPublisher, ServiceRequest
from hil.messaging.ros.node_services import NodeServices
from hil.messaging.ros.parameters import Parameter, Value
from hil.messaging.ros.rmw_zenoh import CLOCK_QOS, LATCHED_QOS
from hil.zenoh_session import DROP_WAIT_US

#: rmw_zenohd's default endpoint, as a session on the router's host reaches it
DEFAULT_ROUTER = "tcp/localhost:7447"
#: the action's name, as ros2_control's joint_trajectory_controller serves it
#: the action under a trajectory controller's name (as the JTC serves it)
ACTION = "follow_joint_trajectory"
#: the action of hil's own trajectory controller
ACTION_NAME = f"joint_trajectory_controller/{ACTION}"
CONTROL_NODE = "hil_control"
SIM_NODE = "hil_sim"


@dataclass(frozen=True)
class RosSettings:
    """Where and as what hil appears in a ROS 2 graph."""

    domain_id: int = 0
    namespace: str = "/"
    distro: str = DEFAULT_DISTRO
    router: str = DEFAULT_ROUTER

    @classmethod
    def from_environment(cls, domain_id: int | None = None, namespace: str | None = None,
                         distro: str | None = None, router: str | None = None) -> RosSettings:
        """Settings given, else ROS's environment (ROS_DOMAIN_ID), else the defaults; a
        ValueError names what is wrong."""
        if domain_id is None:
            text = os.environ.get("ROS_DOMAIN_ID", "0") or "0"
            if not text.isdigit():
                raise ValueError(f"ROS_DOMAIN_ID={text!r} is not a number")
            domain_id = int(text)
        if not 0 <= domain_id <= 232:          # rcl's limit for DDS; rmw_zenoh keeps it
            raise ValueError(f"ROS domain id {domain_id} is outside 0..232")
        namespace = namespace or "/"
        if not namespace.startswith("/"):
            namespace = "/" + namespace
        return cls(domain_id, namespace.rstrip("/") or "/",
                   known_distro(distro or DEFAULT_DISTRO), router or DEFAULT_ROUTER)

    def zenoh_config(self) -> zenoh.Config:
        """A client session of the router, with rmw_zenoh's settings where they apply to a
        client (no multicast scouting; timestamps, which transient-local caches need), and
        hil's bound on how long a put waits for a congested link."""
        config = zenoh.Config()
        config.insert_json5("mode", '"client"')
        config.insert_json5("connect/endpoints", f'["{self.router}"]')
        config.insert_json5("scouting/multicast/enabled", "false")
        config.insert_json5("timestamping/enabled", "true")
        config.insert_json5("transport/link/tx/queue/congestion_control/drop/wait_before_drop",
                            str(DROP_WAIT_US))
        return config


class PlantClock:
    """The plant's time, from the simulator's ``hil/<robot>/sim/clock`` (20 Hz: wall time
    and plant time): for stamping ROS messages on the clock ``use_sim_time`` nodes follow
    (hil sim --ros publishes it as /clock). Between two samples the plant's time goes on at
    the rate of the last two (1 in real time; lock-step runs faster or slower)."""

    def __init__(self, session: zenoh.Session, robot: str):
        self._samples: tuple[tuple[float, float], ...] = ()     # the last two (wall, plant)
        self._since = math.inf          # the wall time of the first sample
        self._subscriber = session.declare_subscriber(key(robot, "sim/clock"),
                                                      direct(self._on_sample))

    def _on_sample(self, sample: zenoh.Sample) -> None:
        try:
            clock = cdr.decode(sample.payload.to_bytes(), cdr.SIM_CLOCK)
        except ValueError:
            return
        self.add(clock.wall_time, clock.sim_time)

    def add(self, wall_time: float, plant_time: float) -> None:
        self._since = min(self._since, wall_time)
        self._samples = (*self._samples[-1:], (wall_time, plant_time))

    def at(self, wall_time: float) -> float | None:
        """The plant's time at ``wall_time`` (s since the epoch); None before the first
        sample's wall time (a message stamped then and sent after it, late on a stalled
        host, would carry a time from before the plant's time was known: CI, 2026-11-29)."""
        samples = self._samples
        if not samples or wall_time < self._since:
            return None
        wall, plant = samples[-1]
        rate = 1.0
        if len(samples) == 2 and samples[1][0] > samples[0][0]:
            rate = max(0.0, (samples[1][1] - samples[0][1]) / (samples[1][0] - samples[0][0]))
        return plant + (wall_time - wall) * rate

    def close(self) -> None:
        self._subscriber.undeclare()


def restamped(payload: bytes, offset: int, clock: PlantClock) -> bytes | None:
    """``payload`` (CDR) with the builtin_interfaces/Time at byte ``offset`` (a header's
    stamp) moved from wall time to the plant's; None while the plant's time is unknown."""
    sec, nanosec = _STAMP.unpack_from(payload, offset)
    plant = clock.at(sec + nanosec * 1e-9)
    if plant is None:
        return None
    return payload[:offset] + _STAMP.pack(*cdr.seconds_and_nanoseconds(plant)) + \
        payload[offset + _STAMP.size:]


_STAMP = struct.Struct("<iI")


#: where the header stamp lies in the CDR of what the controller's face re-stamps (bytes)
JOINT_STATE_STAMP = 4          # after the encapsulation header
FEEDBACK_STAMP = 20            # after it and the goal's 16-byte UUID
DIAGNOSTICS_STAMP = 4
SENSOR_STAMP = 4               # sensor_msgs/Imu's and geometry_msgs/WrenchStamped's
#: each kind of sensor's message type (the kinds of hil.messaging.zenoh_api)
SENSOR_TYPES = {IMU: cdr.IMU, WRENCH: cdr.WRENCH_STAMPED}


def sensor_topic(name: str, kind: str) -> str:
    """The topic of sensor ``name``'s samples: ``<name>_sensor_broadcaster/imu`` (or
    ``/wrench``), the topic of ros2_controllers' imu_sensor_broadcaster (or
    force_torque_sensor_broadcaster) named so (an IMU named ``imu``: the broadcaster's own
    default name)."""
    return f"{name}_sensor_broadcaster/{kind}"


def reset_service_name(settings: RosSettings) -> str:
    """The fully qualified name of the controller's fault reset (std_srvs/Trigger)."""
    return f"{settings.namespace.rstrip('/')}/{CONTROL_NODE}/reset_faults"


def open_context(settings: RosSettings) -> RosContext:
    """A ROS 2 context on a session of its own (its id is the context's in the graph);
    HilError, saying what to do, where no router answers (as hil.zenoh_session.session)."""
    try:
        session = zenoh.open(settings.zenoh_config())
    except zenoh.ZError as exc:
        raise HilError.single(f"cannot reach the Zenoh router at {settings.router}: {exc}",
                              hint="start one (`hil router`, or `ros2 run rmw_zenoh_cpp "
                                   "rmw_zenohd`), give --ros-router, or leave out --ros"
                              ) from None
    return RosContext(session, settings.domain_id)


#: what the trajectory controller's settable parameters mean (the JTC's descriptions, short)
PARAMETER_DESCRIPTIONS = {
    "allow_partial_joints_goal": "goals may name some of the joints (the others hold)",
    "allow_nonzero_velocity_at_trajectory_end": "a goal's last point may have a velocity",
    "interpolate_from_desired_state": "a new goal starts from the last command, not the "
                                      "measured state",
    "allow_integration_in_goal_trajectories": "a point may leave out positions (and "
                                              "velocities): integrated from the one before",
    "reject_unreachable_first_point": "hil's own: refuse a goal whose first point the joints "
                                      "cannot reach in time (false: the JTC's jump)",
    "cmd_timeout": "s after a goal's last point after which it holds (0: never; must exceed "
                   "constraints.goal_time)",
    "constraints.stopped_velocity_tolerance": "rad/s a joint may still move at a goal's end",
    "constraints.goal_time": "s after a goal's last point within which its goal tolerance "
                             "must hold (0: no limit)",
    "trajectory": "rad or m a joint may lag while a goal runs (0: not checked)",
    "goal": "rad or m a joint may end from a goal's last point (0: not checked)",
}


def control_parameters(controller, settings: RosSettings, use_sim_time: bool) -> list[Parameter]:
    """The trajectory controller's parameters by the JTC's names: its joints, interfaces and
    stamps (read-only) and what it lets a client change (settable; applies to the goals
    accepted after the change, as in the JTC)."""
    parameters = controller.parameters
    return [
        Parameter("joints", tuple(controller.joint_names),
                  "the joints the trajectory controller commands, in its order"),
        Parameter("command_interfaces", parameters.command_interfaces,
                  "the interfaces it commands"),
        Parameter("state_interfaces", parameters.state_interfaces, "the interfaces it reads"),
        Parameter("action_monitor_rate", float(parameters.action_monitor_rate),
                  "Hz of the action's feedback"),
        Parameter("ros_distro", settings.distro, "the ROS 2 distribution whose interface "
                  "definitions and type hashes this node uses", read_only_reason="--ros-distro"),
        Parameter("use_sim_time", use_sim_time, "stamps on the plant's time (/clock) instead "
                  "of the wall clock", read_only_reason="--ros-use-sim-time, at start"),
        *(Parameter(name, float(value) if not isinstance(value, bool) else value,
                    PARAMETER_DESCRIPTIONS.get(name) or
                    PARAMETER_DESCRIPTIONS[name.rsplit(".", 1)[-1]], settable=True)
          for name, value in parameters.settable().items())]


def facts_as_parameters(facts: dict[str, Value]) -> list[Parameter]:
    """Read-only parameters of what the process was started with."""
    return [Parameter(name, value, f"the process' {name.replace('_', ' ')}",
                      read_only_reason="set by the process' command line and bus config")
            for name, value in facts.items()]


class RosControlFace(ControlFace):
    """The controller's ROS 2 node, a face of :class:`hil.control_node.ControlNode`."""

    def __init__(self, settings: RosSettings, controller, clock, robot_description: str,
                 reset: Callable[[], tuple[bool, str]] | None = None,
                 plant_clock: PlantClock | None = None, facts: dict[str, Value] | None = None,
                 manager: ControllerManager | None = None):
        """``reset``: resets drive faults, (succeeded, what happened); served as the
        std_srvs/Trigger service ``<namespace>/hil_control/reset_faults``. ``plant_clock``:
        stamp joint states, feedback, diagnostics and goals on the plant's time (ROS's
        use_sim_time) instead of the wall clock; none are published before it is known.
        ``facts``: read-only parameters of the process (robot, rate, ...), beside the
        trajectory controller's own (:func:`control_parameters`). ``manager``: also serve
        controller_manager's services and the forward controllers' command topics."""
        self._plant_clock = plant_clock
        self.context = open_context(settings)
        self._clock = clock
        hashes = self._hashes = TypeHashes(settings.distro)
        self._types = distro_types(settings.distro)
        self._sensors: dict[str, RosPublisher] = {}
        self._own_feedback = FEEDBACK in DISTRO_DEFINITIONS[settings.distro]
        if self._own_feedback:
            encode_feedback_once(controller.joint_names, self._types)
        self.node = RosNode(self.context, CONTROL_NODE, settings.namespace)
        self._joint_states = self.node.publisher("joint_states",
                                                 hashes.message(cdr.JOINT_STATE))
        self._diagnostics = self.node.publisher("diagnostics",
                                                hashes.message(cdr.DIAGNOSTIC_ARRAY))
        self._description = self.node.publisher(
            "robot_description", hashes.message("std_msgs/msg/String"), LATCHED_QOS)
        self._description.put(cdr.encode(cdr.msg("std_msgs/msg/String",
                                                 data=robot_description)))
        self.action = RosTrajectoryActionServer(
            self.node, f"{controller.name}/{ACTION}", FollowJointTrajectory.for_distro(hashes),
            controller, clock,
            on_rejected=self._warn, ros_time=self._ros_time)
        self._reset = reset
        self.controller_manager = None if manager is None else RosControllerManager(
            self.context, settings.namespace, manager, hashes)
        self._reset_service = self.node.service(
            reset_service_name(settings), hashes.service("std_srvs/srv/Trigger"),
            self._on_reset)
        self.services = NodeServices(
            self.node, hashes, [*facts_as_parameters(facts or {}), *control_parameters(
                controller, settings, plant_clock is not None)],
            apply=controller.set_parameters,
            ros_time=self._ros_time)

    def _ros_time(self) -> float:
        """The node's ROS time: the wall clock, or with ``plant_clock`` the plant's time
        (0 until it is known, as rcl's clock reads before the first /clock)."""
        if self._plant_clock is None:
            return time.time()
        plant_time = self._plant_clock.at(time.time())
        return 0.0 if plant_time is None else plant_time

    def _on_reset(self, request: ServiceRequest) -> None:
        # a reset takes up to seconds: answered from a thread of its own, not Zenoh's
        threading.Thread(target=self._answer_reset, args=(request,), daemon=True).start()

    def _answer_reset(self, request: ServiceRequest) -> None:
        succeeded, message = (self._reset() if self._reset is not None
                              else (False, "this controller cannot reset faults"))
        request.reply(cdr.encode(cdr.msg(cdr.TRIGGER_RESPONSE, success=succeeded,
                                         message=message)))

    def _warn(self, message: str) -> None:
        self.publish_diagnostics(DiagnosticStatus("WARN", message, time.time(), self._clock(),
                                                  hardware_id=CONTROL_NODE).encode())

    # Called from the control loop: a put of bytes already encoded (a small share of a cycle
    # in hil up ur3 --ros: docs/performance.md, "2026-12-06, later: figures from code comments"),
    # which waits at most DROP_WAIT_US for a congested router
    # link (zenoh_config). A thread of their own would add a GIL hand-over mid-cycle
    def publish_joint_states(self, payload: bytes) -> None:
        self._put(self._joint_states, payload, JOINT_STATE_STAMP)

    def publish_feedback(self, payload: bytes, state: ControllerState) -> None:
        if self._own_feedback:          # the distribution's own layout (control_msgs 6)
            payload = cdr.encode(feedback_message(state, self._ros_time(), self._types),
                                 self._types)
        self._put(self.action.feedback, payload, FEEDBACK_STAMP)

    def publish_diagnostics(self, payload: bytes) -> None:
        self._put(self._diagnostics, payload, DIAGNOSTICS_STAMP)

    def declare_sensors(self, sensors: tuple[tuple[str, str], ...]) -> None:
        # as ros2_controllers' imu_sensor_broadcaster publishes ~/imu and its
        # force_torque_sensor_broadcaster ~/wrench, one per sensor
        self._sensors = {name: self.node.publisher(sensor_topic(name, kind),
                                                   self._hashes.message(SENSOR_TYPES[kind]))
                         for name, kind in sensors}

    def publish_sensor(self, name: str, payload: bytes) -> None:
        self._put(self._sensors[name], payload, SENSOR_STAMP)

    def _put(self, publisher: RosPublisher, payload: bytes, stamp_at: int) -> None:
        if self._plant_clock is not None:
            payload = restamped(payload, stamp_at, self._plant_clock)
            if payload is None:
                return
        publisher.put(payload)

    def publish_results(self, finished: list) -> None:
        self.action.record_results(finished)

    def close(self) -> None:
        if self.controller_manager is not None:
            self.controller_manager.close()
        self.services.close()
        self.action.close()
        self._reset_service.close()
        if self._plant_clock is not None:
            self._plant_clock.close()
        self.node.close()
        self.context.session.close()


class RosClockFace:
    """The simulator's ROS 2 node: ``/clock`` from the plant's time; ``facts``: its
    read-only parameters (robot, rates, ...)."""

    def __init__(self, settings: RosSettings, facts: dict[str, Value] | None = None):
        self.context = open_context(settings)
        self.node = RosNode(self.context, SIM_NODE, settings.namespace)
        hashes = TypeHashes(settings.distro)
        self._clock = self.node.publisher(
            "/clock", hashes.message("rosgraph_msgs/msg/Clock"), CLOCK_QOS)
        self.services = NodeServices(self.node, hashes, facts_as_parameters(facts or {}))

    def publish(self, sim_time: float) -> None:
        self._clock.put(cdr.time_cdr(sim_time))

    def close(self) -> None:
        self.services.close()
        self.node.close()
        self.context.session.close()


__all__ = ["ACTION_NAME", "CONTROL_NODE", "DEFAULT_ROUTER", "PlantClock", "RosClockFace",
           "RosControlFace", "restamped",
           "RosSettings", "SIM_NODE", "open_context", "reset_service_name"]
