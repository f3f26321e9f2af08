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

import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import zenoh

from hil.messaging import cdr
from hil.messaging.diagnostics import Diagnostic
from hil.messaging.ros.action import RosTrajectoryActionServer
from hil.messaging.ros.interfaces import DEFAULT_DISTRO, FollowJointTrajectory, TypeHashes
from hil.messaging.ros.node import RosContext, RosNode, ServiceRequest
from hil.messaging.ros.rmw_zenoh import CLOCK_QOS, LATCHED_QOS
from hil.zenoh_session import DROP_WAIT_US

#: rmw_zenohd's default endpoint, as a session on the router's host reaches it
DEFAULT_ROUTER = "tcp/localhost:7447"
#: the action's name, as ros2_control's joint_trajectory_controller serves it
ACTION_NAME = "joint_trajectory_controller/follow_joint_trajectory"
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
        settings = cls(domain_id, namespace.rstrip("/") or "/", distro or DEFAULT_DISTRO,
                       router or DEFAULT_ROUTER)
        TypeHashes(settings.distro)            # an unknown distribution fails here
        return settings

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


def reset_service_name(settings: RosSettings) -> str:
    """The fully qualified name of the controller's fault reset (std_srvs/Trigger)."""
    return f"{settings.namespace.rstrip('/')}/{CONTROL_NODE}/reset_faults"


def open_context(settings: RosSettings) -> RosContext:
    """A ROS 2 context on a session of its own (its id is the context's in the graph)."""
    try:
        session = zenoh.open(settings.zenoh_config())
    except zenoh.ZError as exc:
        raise ConnectionError(f"cannot reach the Zenoh router at {settings.router}: {exc} "
                              "(start one: `hil router` or `ros2 run rmw_zenoh_cpp rmw_zenohd`)"
                              ) from None
    return RosContext(session, settings.domain_id)


class RosControlFace:
    """The controller's ROS 2 node; made by :meth:`ControlNode`'s ``ros`` factory."""

    def __init__(self, settings: RosSettings, controller, clock, robot_description: str,
                 reset: Callable[[], tuple[bool, str]] | None = None):
        """``reset``: resets drive faults, (succeeded, what happened); served as the
        std_srvs/Trigger service ``<namespace>/hil_control/reset_faults``."""
        self.context = open_context(settings)
        self._clock = clock
        hashes = TypeHashes(settings.distro)
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
            self.node, ACTION_NAME, FollowJointTrajectory.for_distro(hashes), controller, clock,
            on_rejected=self._warn)
        self._reset = reset
        self._reset_service = self.node.service(
            reset_service_name(settings), hashes.service("std_srvs/srv/Trigger"),
            self._on_reset)

    def _on_reset(self, request: ServiceRequest) -> None:
        # a reset takes up to seconds: answered from a thread of its own, not Zenoh's
        threading.Thread(target=self._answer_reset, args=(request,), daemon=True).start()

    def _answer_reset(self, request: ServiceRequest) -> None:
        succeeded, message = (self._reset() if self._reset is not None
                              else (False, "this controller cannot reset faults"))
        request.reply(cdr.encode(cdr.msg(cdr.TRIGGER_RESPONSE, success=succeeded,
                                         message=message)))

    def _warn(self, message: str) -> None:
        self.publish_diagnostics(Diagnostic("WARN", message, time.time(), self._clock(),
                                            hardware_id=CONTROL_NODE).encode())

    # Called from the control loop: a put of bytes already encoded (measured in hil up ur3
    # --ros: p50 20 us, p99 30 us), which waits at most DROP_WAIT_US for a congested router
    # link (zenoh_config). A thread of their own would add a GIL hand-over mid-cycle
    def publish_joint_states(self, payload: bytes) -> None:
        self._joint_states.put(payload)

    def publish_feedback(self, payload: bytes) -> None:
        self.action.feedback.put(payload)

    def publish_diagnostics(self, payload: bytes) -> None:
        self._diagnostics.put(payload)

    def record_results(self, finished: list) -> None:
        self.action.record_results(finished)

    def close(self) -> None:
        self.action.close()
        self._reset_service.close()
        self.node.close()
        self.context.session.close()


class RosClockFace:
    """The simulator's ROS 2 node: ``/clock`` from the plant's time."""

    def __init__(self, settings: RosSettings):
        self.context = open_context(settings)
        self.node = RosNode(self.context, SIM_NODE, settings.namespace)
        self._clock = self.node.publisher(
            "/clock", TypeHashes(settings.distro).message("rosgraph_msgs/msg/Clock"), CLOCK_QOS)

    def publish(self, sim_time: float) -> None:
        self._clock.put(cdr.time_cdr(sim_time))

    def close(self) -> None:
        self.node.close()
        self.context.session.close()


__all__ = ["ACTION_NAME", "CONTROL_NODE", "DEFAULT_ROUTER", "RosClockFace", "RosControlFace",
           "RosSettings", "SIM_NODE", "open_context", "reset_service_name"]
