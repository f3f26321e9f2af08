"""A trajectory goal checked against the joints' limits and planned between its points,
before it meets the controller's state (:class:`hil.controllers.JointTrajectoryController`
does this without its lock: a 10,000-point goal takes milliseconds)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hil.controllers.goal import (
    INVALID_JOINTS, MAX_POINTS, GoalRejected, JointTolerance, TrajectoryGoal, check_start_time,
    first_index, goal_arrays,
)
from hil.controllers.parameters import FLOAT_EPSILON, JtcParameters, SegmentTolerances, resolve
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
    #: over every controller joint (the JTC fills a partial goal with the others' holds)
    tolerances: SegmentTolerances
    #: why the goal's own tolerances were not taken (the JTC logs it and runs the goal with
    #: its defaults), or None
    tolerance_warning: str | None = None


def plan_goal(joints: JointLimitTable, parameters: JtcParameters,
              goal: TrajectoryGoal) -> GoalPlan:
    """Check a goal as the JTC's validate_trajectory_msg does, and against the joints'
    limits, and plan its segments between points; raise GoalRejected naming the joint and
    point at the first problem."""
    indices = _check_joints(joints, goal)
    if not parameters.allow_partial_joints_goal and len(indices) != len(joints.names):
        raise GoalRejected(
            f"the goal names {len(indices)} of the controller's {len(joints.names)} joints and "
            "allow_partial_joints_goal is false (the JTC: \"Joints on incoming trajectory "
            f"don't match the controller joints.\"): name all of {', '.join(joints.names)}",
            INVALID_JOINTS)
    if not goal.points:
        raise GoalRejected("the trajectory has no points")
    if goal.has_efforts:
        raise GoalRejected("Trajectories with effort fields are only supported for controllers "
                           "using the 'effort' command interface (hil's hardware interface "
                           "exports position and velocity)")
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
    if not parameters.allow_nonzero_velocity_at_trajectory_end:
        moving = np.abs(velocities[-1]) > FLOAT_EPSILON
        if moving.any():
            k = int(np.argmax(moving))
            raise GoalRejected(
                f"Velocity of last trajectory point of joint {goal.joint_names[k]} is not "
                f"zero: {velocities[-1, k]:.15f} (allow_nonzero_velocity_at_trajectory_end "
                "is false)")
    check_start_time(goal)
    tolerances, warning = goal_tolerances(parameters, goal)
    return GoalPlan(indices, Spline.between(times, positions, velocities, accelerations, order),
                    tolerances, warning)


def goal_tolerances(parameters: JtcParameters,
                    goal: TrajectoryGoal) -> tuple[SegmentTolerances, str | None]:
    """The tolerances a goal runs with (tolerances.hpp, get_segment_tolerances(goal)): its
    own over the controller's defaults; for an illegal value (negative but -1) or a joint the
    controller does not have, the defaults and why (the JTC logs it and runs the goal)."""
    defaults = parameters.defaults()
    try:
        goal_time = resolve(defaults.goal_time, goal.goal_time_tolerance)
    except ValueError:
        return defaults, (f"Specified illegal goal_time_tolerance: "
                          f"{goal.goal_time_tolerance:f}. Using default tolerances")
    path = [defaults.path_position.copy(), defaults.path_velocity.copy()]
    end = [defaults.goal_position.copy(), defaults.goal_velocity.copy()]
    for what, given, arrays in (("path_tolerance", goal.path_tolerance, path),
                                ("goal_tolerance", goal.goal_tolerance, end)):
        problem = _resolve_joints(parameters.joints, given, arrays)
        if problem:
            return defaults, problem.format(what)
    return SegmentTolerances(*path, *end, goal_time=goal_time), None


def _resolve_joints(joints: tuple[str, ...], given: tuple[JointTolerance, ...],
                    arrays: list[np.ndarray]) -> str | None:
    """Resolve each joint's tolerances into ``arrays`` (position, velocity); the JTC's
    complaint ('{}': which list) at the first it cannot take."""
    for tolerance in given:
        if tolerance.name not in joints:
            return (f"joint '{tolerance.name}' specified in goal.{{}} does not exist. "
                    "Using default tolerances.")
        i = joints.index(tolerance.name)
        for values, interface, value in ((arrays[0], "position", tolerance.position),
                                         (arrays[1], "velocity", tolerance.velocity)):
            try:
                values[i] = resolve(values[i], value)
            except ValueError:
                return (f"joint '{tolerance.name}' specified in goal.{{}} has a invalid "
                        f"{interface} tolerance. Using default tolerances.")
    return None


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
