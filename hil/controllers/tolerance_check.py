"""How a running goal ends, judged each cycle from its tracking errors as the JTC's update
does (ros2_controllers jazzy, joint_trajectory_controller.cpp; each behaviour's source is
cited in tests/test_jtc_semantics.py): the path tolerances while the trajectory runs (and
on its first sample), the goal tolerances from its last point on, within ``goal_time``
(0: without a time limit) or the command timeout."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from hil.controllers.active_goal import ActiveGoal
from hil.controllers.goal import (
    GOAL_TIME_ABORT, GOAL_TOLERANCE_VIOLATED, PATH_ABORT, PATH_TOLERANCE_VIOLATED, REACHED,
    SUCCESSFUL, GoalResult, GoalStatus,
)
from hil.controllers.parameters import JtcParameters

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Ending:
    """A goal's result, and whether the joints stop (hold or ramp down) with it."""

    result: GoalResult
    stop: bool


def judge(goal: ActiveGoal, late: float, first: bool, difference: np.ndarray,
          velocity_error: np.ndarray, continuous: np.ndarray, parameters: JtcParameters,
          joint_names: Sequence[str]) -> Ending | None:
    """How ``goal`` ends ``late`` seconds after its last point (negative while the
    trajectory runs), or None while it goes on. ``difference`` is desired - measured
    position (continuous joints: wrapped here to the shortest angle), ``first`` whether this
    is the goal's first sample."""
    wrapped = (difference + np.pi) % (2 * np.pi) - np.pi
    error = np.where(continuous, wrapped, difference)
    tolerances = goal.tolerances
    before_last_point = late < 0.0
    if before_last_point or first:
        broken = outside(error, velocity_error, tolerances.path_position,
                         tolerances.path_velocity)
        if broken is not None:
            log.warning("goal %s: joint '%s' %s at t=%.3f s", goal.goal_id,
                        joint_names[broken[0]], broken[1], late + goal.spline.end)
            return Ending(GoalResult(GoalStatus.ABORTED, PATH_TOLERANCE_VIOLATED, PATH_ABORT),
                          stop=True)
    if before_last_point:
        return None
    broken = outside(error, velocity_error, tolerances.goal_position, tolerances.goal_velocity)
    timeout = parameters.effective_cmd_timeout()
    if broken is not None and timeout > 0 and late > timeout:
        # the JTC holds on a command timeout, then (holding, no tolerance is checked)
        # reports the goal reached on its next update: the same result here
        log.warning("goal %s: Aborted due to command timeout", goal.goal_id)
        return Ending(GoalResult(GoalStatus.SUCCEEDED, SUCCESSFUL, REACHED), stop=True)
    if broken is None:
        return Ending(GoalResult(GoalStatus.SUCCEEDED, SUCCESSFUL, REACHED), stop=False)
    if tolerances.goal_time != 0 and late > tolerances.goal_time:
        log.warning("goal %s: joint '%s' %s, %.3f s after the last point", goal.goal_id,
                    joint_names[broken[0]], broken[1], late)
        return Ending(GoalResult(GoalStatus.ABORTED, GOAL_TOLERANCE_VIOLATED,
                                 GOAL_TIME_ABORT.format(late)), stop=True)
    return None


def outside(error: np.ndarray, velocity_error: np.ndarray, position: np.ndarray,
            velocity: np.ndarray) -> tuple[int, str] | None:
    """The first joint outside its tolerances (check_state_tolerance_per_joint: a tolerance
    of 0 is not checked) and how, or None."""
    for what, values, tolerance in (("position error", error, position),
                                    ("velocity error", velocity_error, velocity)):
        broken = (tolerance > 0) & (np.abs(values) > tolerance)
        # not .any(), a Python function in numpy and slower (docs/performance.md,
        # "2026-12-01: the in-process cycle in a fifth fewer instructions")
        if np.count_nonzero(broken):
            i = int(np.argmax(broken))
            return i, f"{what} {values[i]:+.4f} exceeds its tolerance {tolerance[i]:g}"
    return None
