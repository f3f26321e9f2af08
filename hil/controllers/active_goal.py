"""A goal the joint trajectory controller accepts: its plan (:mod:`hil.controllers.planning`)
started from the controller's state at the moment it takes over, as the JTC's
add_new_trajectory_msg and the first update of a new trajectory do."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hil.controllers.goal import GoalRejected, GoalResult, TrajectoryGoal
from hil.controllers.parameters import JtcParameters, SegmentTolerances
from hil.controllers.planning import GoalPlan, JointLimitTable, check_reachable
from hil.controllers.spline import Spline


@dataclass
class ActiveGoal:
    goal_id: str
    indices: np.ndarray            # controller joint index of each goal joint
    spline: Spline                 # on the goal's clock: 0 = its stamp
    start: float                   # the goal's stamp on the controller's clock
    end: float
    tolerances: SegmentTolerances  # over every controller joint
    sampled: bool = False
    result: GoalResult | None = None


def start_goal(goal_id: str, goal: TrajectoryGoal, plan: GoalPlan, limits: JointLimitTable,
               parameters: JtcParameters, now: float,
               before: tuple[np.ndarray, np.ndarray, np.ndarray]) -> ActiveGoal:
    """The planned goal from the controller's state ``now``: its clock from its stamp (now
    when none), continuous joints on the turn nearest where they are, the first segment from
    ``before`` (the JTC's point before the trajectory, over the goal's joints) to point 0.
    Points it leaves to allow_integration_in_goal_trajectories are integrated from that
    state: planned again here only where it differs from the state when the goal arrived.
    Raises GoalRejected for a stamped goal that ends in the past, or (with
    reject_unreachable_first_point) a first point out of reach."""
    indices = plan.indices
    stamp = now if goal.start_time is None else goal.start_time
    if stamp + plan.end < now:
        raise GoalRejected(f"Received trajectory with non-zero start time ({stamp:f}) that "
                           f"ends in the past ({stamp + plan.end:f}); now is {now:f}")
    here, v0, a0 = before
    spline = plan.spline_from(limits, goal.joint_names, here, v0, a0, at=now - stamp)
    if plan.integrating is None or plan.integrating.given.positions[0]:
        # point 0 as given goes on the turn nearest the joints; integrated, it is there
        turns = np.round((spline.points[0] - here) / (2 * np.pi))
        spline.shift(np.where(limits.continuous[indices], -turns * 2 * np.pi, 0.0))
    available = float(spline.t1[0]) - (now - stamp)
    spline.start_from(here, v0, a0, at=now - stamp)
    if parameters.reject_unreachable_first_point:
        check_reachable(limits, parameters, indices, here, spline, now - stamp, available)
    return ActiveGoal(goal_id, indices, spline, stamp, stamp + spline.end, plan.tolerances)
