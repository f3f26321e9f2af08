"""The controller's faces to other processes: where the control loop's outputs go.

A :class:`ControlFace` takes what the loop produced, encoded once as CDR of hil's messages,
and puts it where its clients look: :class:`ZenohControlFace` on hil's own keys
(:mod:`hil.messaging.keys`), :class:`hil.messaging.ros.face.RosControlFace` on rmw_zenoh's.
Every method is called from the control loop and must take microseconds (a put of bytes,
a hand-over to a thread); a face publishes what it has a use for and leaves the rest to
the no-ops here.
"""

from __future__ import annotations

from collections.abc import Callable

import zenoh

from hil.controllers import ControllerState, GoalResult
from hil.controllers.manager import ControllerManager
from hil.messaging.action import TrajectoryActionServer
from hil.messaging.controller_manager import ControllerManagerServer
from hil.messaging.samples import ControlSamples
from hil.messaging.zenoh_api import (
    ControlSamplesPublisher, DiagnosticsPublisher, JointStatePublisher, SensorPublisher,
)


class ControlFace:
    """One face of the controller; the control node calls each of its faces in turn."""

    def publish_joint_states(self, payload: bytes) -> None:
        """sensor_msgs/JointState of every movable joint."""

    def publish_feedback(self, payload: bytes, state: ControllerState) -> None:
        """The active goal's FollowJointTrajectory FeedbackMessage, and the controller's
        state it was made from (for a face whose clients expect another layout)."""

    def publish_diagnostics(self, payload: bytes) -> None:
        """A diagnostic_msgs/DiagnosticArray: a fault, a fault reset."""

    def publish_results(self, finished: list[tuple[str, GoalResult]]) -> None:
        """The goals that ended since the last call, (goal id, result)."""

    def publish_samples(self, batch: ControlSamples) -> None:
        """A batch of recorded control cycles."""

    def declare_sensors(self, sensors: tuple[tuple[str, str], ...]) -> None:
        """The sensors, (name, kind: IMU or WRENCH of hil.messaging.zenoh_api), that
        :meth:`publish_sensor` will be given samples of (declared before the loop cycles: a
        declaration takes longer than a cycle may)."""

    def publish_sensor(self, name: str, payload: bytes) -> None:
        """A sample of sensor ``name``: sensor_msgs/Imu or geometry_msgs/WrenchStamped."""

    def close(self) -> None:
        """Undeclare everything; called once, after the loop's last cycle."""


class ZenohControlFace(ControlFace):
    """hil's own keys: joint states, the trajectory action (goals in, feedback and results
    out), the controller manager, diagnostics, control samples and the fault reset query."""

    def __init__(self, session: zenoh.Session, robot: str, manager: ControllerManager,
                 stamp_to_clock: Callable[[float], float],
                 reset: Callable[[], tuple[bool, str]]):
        self.server = TrajectoryActionServer(session, robot, manager.trajectory, stamp_to_clock)
        self.server.on_reset = reset
        self.manager = ControllerManagerServer(session, robot, manager)
        self._joint_states = JointStatePublisher(session, robot)
        self._samples = ControlSamplesPublisher(session, robot)
        self._diagnostics = DiagnosticsPublisher(session, robot)
        self._session, self._robot = session, robot
        self._sensors: dict[str, SensorPublisher] = {}

    def publish_joint_states(self, payload: bytes) -> None:
        self._joint_states.put(payload)

    def publish_feedback(self, payload: bytes, state: ControllerState) -> None:
        self.server.put_feedback(payload)

    def publish_diagnostics(self, payload: bytes) -> None:
        self._diagnostics.put(payload)

    def publish_results(self, finished: list[tuple[str, GoalResult]]) -> None:
        self.server.publish_results(finished)

    def publish_samples(self, batch: ControlSamples) -> None:
        self._samples.publish(batch)

    def declare_sensors(self, sensors: tuple[tuple[str, str], ...]) -> None:
        self._sensors = {name: SensorPublisher(self._session, self._robot, name, kind)
                         for name, kind in sensors}

    def publish_sensor(self, name: str, payload: bytes) -> None:
        self._sensors[name].put(payload)

    def close(self) -> None:
        self.server.close()
        self.manager.close()
        self._joint_states.close()
        self._samples.close()
        self._diagnostics.close()
        for publisher in self._sensors.values():
            publisher.close()
