"""A trajectory goal checked against the joints' limits and planned between its points,
before it meets the controller's state (:class:`hil.controllers.JointTrajectoryController`
does this without its lock: a 10,000-point goal takes milliseconds)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hil.controllers.goal import (
    INVALID_JOINTS, MAX_POINTS, Defaults, GoalRejected, JointTolerance, TrajectoryGoal,
    check_tolerances, first_index, goal_arrays,
)
from hil.controllers.spline import Spline
from hil.description import Joint, JointType, RobotDescription


@dataclass(frozen=True)
class JointLimitTable:
    """The commanded joints' limits as arrays, in the controller's joint order (no lower or
    upper limit: -inf, inf), and the mimic joints by their leaders."""

    names: tuple[str, ...]
    lower: np.ndarray
    upper: np.ndarray
    velocity: np.ndarray
    continuous: np.ndarray
    mimic: dict[str, str]

    @classmethod
    def of(cls, robot: RobotDescription, joints: tuple[Joint, ...]) -> JointLimitTable:
        return cls(
            tuple(j.name for j in joints),
            np.array([j.limits.lower if j.limits and j.limits.lower is not None else -np.inf
                      for j in joints]),
            np.array([j.limits.upper if j.limits and j.limits.upper is not None else np.inf
                      for j in joints]),
            np.array([j.limits.velocity if j.limits else np.inf for j in joints]),
            np.array([j.type is JointType.CONTINUOUS for j in joints]),
            {j.name: j.mimic.joint for j in robot.joints if j.mimic})


@dataclass
class GoalPlan:
    """A goal checked and planned between its points."""

    indices: np.ndarray            # controller joint index of each goal joint
    spline: Spline
    path: tuple[np.ndarray, np.ndarray]
    tolerance: tuple[np.ndarray, np.ndarray]
    goal_time_tolerance: float


def plan_goal(joints: JointLimitTable, defaults: Defaults, goal: TrajectoryGoal) -> GoalPlan:
    """Check a goal against the joints' limits and plan its segments between points; raise
    GoalRejected naming the joint and point at the first problem."""
    indices = _check_joints(joints, goal)
    if not goal.points:
        raise GoalRejected("the trajectory has no points")
    if len(goal.points) > MAX_POINTS:
        raise GoalRejected(f"the trajectory has {len(goal.points)} points; this controller "
                           f"takes at most {MAX_POINTS} (split it into several goals, or "
                           "sample it more coarsely)")
    times, positions, velocities, accelerations, order = goal_arrays(goal)
    lower, upper = joints.lower[indices], joints.upper[indices]
    limit, continuous = joints.velocity[indices], joints.continuous[indices]
    outside = ~continuous & ((positions < lower) | (positions > upper))
    if outside.any():
        p, k = first_index(outside)
        raise GoalRejected(f"point {p} joint '{goal.joint_names[k]}' position "
                           f"{positions[p, k]:g} is outside its limits [{lower[k]:g}, "
                           f"{upper[k]:g}]")
    too_fast = np.abs(velocities) > limit
    if too_fast.any():
        p, k = first_index(too_fast)
        raise GoalRejected(f"point {p} joint '{goal.joint_names[k]}' velocity "
                           f"{velocities[p, k]:g} exceeds its limit {limit[k]:g}")
    # continuous joints: each point on the turn nearest the point before (the first is
    # put on the turn nearest the joint's state when the goal starts)
    positions[:, continuous] = np.unwrap(positions[:, continuous], axis=0)
    if len(times) > 1:
        implied = np.diff(positions, axis=0) / np.diff(times)[:, None]
        too_fast = np.abs(implied) > limit * (1 + 1e-9)
        if too_fast.any():
            p, k = first_index(too_fast)
            raise GoalRejected(
                f"point {p + 1} joint '{goal.joint_names[k]}' needs {abs(implied[p, k]):.4g}"
                f" on average from point {p}, above its velocity limit {limit[k]:g}")
    check_tolerances(goal)
    path = _tolerances(goal.path_tolerance, goal.joint_names,
                            defaults.path_position_tolerance, 0.0)
    tolerance = _tolerances(goal.goal_tolerance, goal.joint_names,
                                 defaults.goal_position_tolerance,
                                 defaults.goal_velocity_tolerance)
    goal_time = (goal.goal_time_tolerance if goal.goal_time_tolerance > 0 else
                 defaults.goal_time_tolerance)
    return GoalPlan(indices, Spline.between(times, positions, velocities, accelerations, order),
                 path, tolerance, goal_time)


def _check_joints(joints: JointLimitTable, goal: TrajectoryGoal) -> np.ndarray:
    names = goal.joint_names
    if not names:
        raise GoalRejected("the goal names no joints", INVALID_JOINTS)
    for name in names:
        if name in joints.mimic:
            raise GoalRejected(f"joint '{name}' mimics '{joints.mimic[name]}' and cannot be "
                               "commanded; command its leader", INVALID_JOINTS)
        if name not in joints.names:
            raise GoalRejected(f"unknown joint '{name}'; this controller has: "
                               f"{', '.join(joints.names)}", INVALID_JOINTS)
    if len(set(names)) != len(names):
        raise GoalRejected("a joint is named twice in the goal", INVALID_JOINTS)
    return np.array([joints.names.index(n) for n in names])


def _tolerances(given: tuple[JointTolerance, ...], names: tuple[str, ...],
                position_default: float, velocity_default: float):
    position = np.full(len(names), position_default)
    velocity = np.full(len(names), velocity_default)
    for tolerance in given:
        k = names.index(tolerance.name)
        if tolerance.position != 0:
            position[k] = tolerance.position
        if tolerance.velocity != 0:
            velocity[k] = tolerance.velocity
    return position, velocity
