"""Joint space to the axes and back: the robot's transmissions, the gravity feed-forward
the drives' configs ask for, and the check that keeps implausible feedback out of the joint
state."""

from __future__ import annotations

import numpy as np

from hil.description import RobotDescription
from hil.hardware.axis import Axis, AxisFault, FaultKind, answers_of
from hil.hardware.feedback import JointFeedback, PlausibilityCheck
from hil.transmissions import TransmissionStack, build_transmissions


class JointMapping:
    """The joints of ``robot`` (``joint_names`` order) onto ``axes`` (each moving its
    config's actuator) and back."""

    def __init__(self, robot: RobotDescription, joint_names: tuple[str, ...],
                 axes: list[Axis]):
        self.joint_names = joint_names
        self.axes = axes
        #: joints (joint_names order) <-> actuators (axes order) in one map
        self.transmissions = TransmissionStack(
            build_transmissions(robot), joint_names, tuple(a.config.actuator for a in axes))
        #: whether each axis' config asks the gravity feed-forward
        self._gravity_axes = np.array([a.config.torque_feed_forward == "gravity" for a in axes])
        self._gravity = None
        if self._gravity_axes.any():
            # imported here: the controller loads MuJoCo only where a drive asks for it
            from hil.hardware.gravity import GravityModel
            self._gravity = GravityModel(robot, joint_names)
        self._no_torques = [0.0] * len(axes)
        self._plausibility = PlausibilityCheck(robot, joint_names)
        self._all_heard = False

    # --- to the axes ------------------------------------------------------------------

    def actuator_commands(self, positions, velocities
                          ) -> tuple[list[float], list[float], list[float]]:
        """Each axis' target, its velocity and its torque feed-forward (motor side) for
        joints commanded to ``positions`` at ``velocities``."""
        return (self.transmissions.joint_to_actuator_position(positions).tolist(),
                self.transmissions.joint_to_actuator_velocity(velocities).tolist(),
                self._feed_forward_torques(positions))

    def _feed_forward_torques(self, positions) -> list[float]:
        """Each axis' torque feed-forward (N·m, motor side): what holds its joints against
        gravity at ``positions``, for the drives whose config asks (0 for the others)."""
        if self._gravity is None:
            return self._no_torques
        torques = self.transmissions.joint_to_actuator_effort(self._gravity.torques(positions))
        return np.where(self._gravity_axes, torques, 0.0).tolist()

    # --- from the axes ----------------------------------------------------------------

    def joint_feedback(self) -> tuple[JointFeedback, list[tuple[str, AxisFault]]]:
        """The axes' last answers in joint space, and what no joint can produce: (joint,
        the fault of its first drive) for each joint whose feedback is implausible (it keeps
        its last plausible values; see :class:`~hil.hardware.feedback.PlausibilityCheck`)."""
        answers, states = answers_of(self.axes)
        n = len(states)
        measured = np.array(answers)
        joint = self.transmissions.actuator_to_joint_feedback(measured)
        checked, implausible = self._plausibility.check(
            JointFeedback(joint[:n], joint[n:2 * n], joint[2 * n:], measured[2 * n:], states),
            self._heard_joints())
        if not implausible:
            return checked, []
        return checked, [self._implausible(self.joint_names[k], text)
                         for k, text in implausible]

    def _implausible(self, joint: str, text: str) -> tuple[str, AxisFault]:
        axis = next(a for a in self.axes if joint in a.config.joints)     # its first drive
        return joint, axis.found(FaultKind.IMPLAUSIBLE, text)

    def _heard_joints(self) -> np.ndarray | None:
        """Per joint: all its drives have answered at least once (before that, their values
        are defaults, not measurements); None: every joint's have."""
        # once every drive has answered (from the first cycles on) that stays so
        self._all_heard = self._all_heard or all(axis.feedback.heard for axis in self.axes)
        if self._all_heard:
            return None
        heard = {j: True for j in self.joint_names}
        for axis in self.axes:
            for joint in axis.config.joints:
                heard[joint] = heard.get(joint, True) and axis.feedback.heard
        return np.array([heard[j] for j in self.joint_names])
