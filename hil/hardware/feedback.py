"""What a hardware interface reads each cycle, and the check that keeps feedback no joint
can produce (a frame the drive did not send, wrong encoder or transmission settings) out of
the joint state."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hil.description import RobotDescription


@dataclass
class JointFeedback:
    """One cycle's measurements: joint space, plus what each drive reported of itself
    (``HardwareInterface.actuator_names`` order)."""

    positions: np.ndarray
    velocities: np.ndarray
    efforts: np.ndarray
    motor_torques: np.ndarray       # N·m on the motor shaft, as the drive reports it
    drive_states: tuple[str, ...]   # each drive's state in its own protocol's words


#: measured joint positions beyond the limits by more than this part of the joint's range
#: (plus REACH_SLACK, rad or m) cannot be real: a joint overshoots its limit a little at most
REACH_MARGIN = 0.1
REACH_SLACK = 0.01
#: measured joint speeds beyond this many times the velocity limit (plus 1) cannot be real
SPEED_MARGIN = 10.0


class PlausibilityCheck:
    """Positions beyond a joint's reach or speeds beyond its top speed are implausible: the
    joint keeps its last plausible values and the check says why, per joint."""

    def __init__(self, robot: RobotDescription, joint_names: tuple[str, ...]):
        self.joint_names = joint_names
        self.reach, self.speed_limit = _reach(robot, joint_names)
        # the same bounds as Python floats, for the common case's check (_all_plausible)
        self._bounds = [(float(low), float(high), float(speed))
                        for low, high, speed in zip(*self.reach, self.speed_limit)]
        self._plausible: JointFeedback | None = None

    def check(self, feedback: JointFeedback, heard: np.ndarray | None = None
              ) -> tuple[JointFeedback, list[tuple[int, str]]]:
        """The feedback to use, and (joint index, why) for each implausible joint; joints
        not ``heard`` yet (None: every joint is) carry defaults and are not judged."""
        if heard is None and self._all_plausible(feedback):
            self._plausible = feedback
            return feedback, []
        low, high = self.reach
        # not inside, rather than beyond: a NaN (a float protocol's, e.g. ODrive's) is
        # implausible too, and never reaches a controller
        bad = ~((feedback.positions >= low) & (feedback.positions <= high)
                & (np.abs(feedback.velocities) <= self.speed_limit))
        if heard is not None:
            bad &= heard
        # not bad.any(), a Python function in numpy and slower (docs/performance.md,
        # "2026-12-01: the in-process cycle in a fifth fewer instructions")
        if not np.count_nonzero(bad):
            self._plausible = feedback
            return feedback, []
        why = [(k, f"sent implausible feedback: joint '{self.joint_names[k]}' measured at "
                   f"{feedback.positions[k]:+.4g} moving {feedback.velocities[k]:+.4g}/s, beyond "
                   f"what it can reach ([{low[k]:.4g}, {high[k]:.4g}], speed "
                   f"{self.speed_limit[k]:.4g}): a frame the drive did not send, or the "
                   "encoder or transmission settings of the bus config are wrong")
               for k in np.nonzero(bad)[0]]
        last = self._plausible
        positions, velocities = feedback.positions.copy(), feedback.velocities.copy()
        positions[bad] = (last.positions[bad] if last
                          else np.clip(np.nan_to_num(positions), low, high)[bad])
        velocities[bad] = last.velocities[bad] if last else 0.0
        return JointFeedback(positions, velocities, feedback.efforts, feedback.motor_torques,
                             feedback.drive_states), why

    def _all_plausible(self, feedback: JointFeedback) -> bool:
        """Whether every joint is within its bounds, compared as Python floats: a third of
        the time of numpy's five calls on a robot's few joints, at every cycle. False also
        for a NaN, as in the arrays' check."""
        for position, velocity, (low, high, speed) in zip(
                feedback.positions.tolist(), feedback.velocities.tolist(), self._bounds):
            if not (low <= position <= high and -speed <= velocity <= speed):
                return False
        return True


def _reach(robot: RobotDescription, names: tuple[str, ...]
           ) -> tuple[tuple[np.ndarray, np.ndarray], np.ndarray]:
    """((lowest, highest) position, top speed) a joint's measurement can plausibly show."""
    low, high, speed = [], [], []
    for name in names:
        limits = robot.joint(name).limits
        if limits is None or limits.lower is None or limits.upper is None:
            low.append(-np.inf)
            high.append(np.inf)
        else:
            margin = REACH_MARGIN * (limits.upper - limits.lower) + REACH_SLACK
            low.append(limits.lower - margin)
            high.append(limits.upper + margin)
        speed.append(SPEED_MARGIN * limits.velocity + 1.0 if limits and limits.velocity > 0
                     else np.inf)
    return (np.array(low), np.array(high)), np.array(speed)
