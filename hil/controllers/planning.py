"""A trajectory goal checked against the joints' limits and planned between its points,
before it meets the controller's state (:class:`hil.controllers.JointTrajectoryController`
does this without its lock: a 10,000-point goal takes milliseconds)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hil.controllers.goal import (
    INVALID_JOINTS, MAX_POINTS, GoalArrays, GoalRejected, JointTolerance, TrajectoryGoal,
    check_start_time, first_index, goal_arrays,
)
from hil.controllers.integration import integrated
from hil.controllers.parameters import FLOAT_EPSILON, JtcParameters, SegmentTolerances, resolve
from hil.controllers.spline import Spline
from hil.description import Joint, JointType, RobotDescription

#: a first point due now may lie this far from where a joint is when its constraint sets no
#: goal tolerance (hil's choice: the JTC would jump there)
FIRST_POINT_SLACK = 0.02


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
    #: None where points are integrated from the state the goal starts from
    #: (:attr:`integrating`) until :meth:`spline_from` plans them
    spline: Spline | None
    #: over every controller joint (the JTC fills a partial goal with the others' holds)
    tolerances: SegmentTolerances
    #: why the goal's own tolerances were not taken (the JTC logs it and runs the goal with
    #: its defaults), or None
    tolerance_warning: str | None = None
    #: the points, where some leave their positions to allow_integration_in_goal_trajectories
    integrating: GoalArrays | None = None
    #: the state (p0, v0, a0, at) an integrating goal's spline was planned from
    _planned_from: tuple | None = field(default=None, init=False, repr=False)

    @property
    def end(self) -> float:
        """The last point's time on the goal's clock."""
        return self.spline.end if self.spline is not None else float(
            self.integrating.times[-1])

    def spline_from(self, joints: JointLimitTable, names: tuple[str, ...], p0: np.ndarray,
                    v0: np.ndarray, a0: np.ndarray, at: float) -> Spline:
        """The segments; a goal whose points are integrated, from the state (``p0``, ``v0``,
        ``a0``: the point before the trajectory) at ``at`` on the goal's clock, after checking
        them against the limits: planned again only from a state other than the last."""
        state = (p0, v0, a0, np.array(at))
        planned = self._planned_from is not None and all(
            np.array_equal(mine, other) for mine, other in zip(state, self._planned_from))
        if self.integrating is not None and not planned:
            self.spline = _planned(joints, self.indices, names,
                                   integrated(self.integrating, p0, v0, a0, at), unwrap=False)
            self._planned_from = state
        return self.spline


def plan_goal(joints: JointLimitTable, parameters: JtcParameters,
              goal: TrajectoryGoal) -> GoalPlan:
    """Check a goal as the JTC's validate_trajectory_msg does, and against the joints'
    limits, and plan its segments between points; raise GoalRejected naming the joint and
    point at the first problem. A goal whose points are integrated is checked against the
    limits when it is planned from a state (:meth:`GoalPlan.spline_from`)."""
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
    arrays = goal_arrays(goal, parameters.allow_integration_in_goal_trajectories)
    # validate_trajectory_msg checks the last point's velocities as the goal gives them
    # (before a linear goal's are zeroed)
    last = arrays.velocities[-1].copy() if arrays.given.velocities[-1] else np.zeros(0)
    spline = None if arrays.integrates else _planned(joints, indices, goal.joint_names, arrays)
    moving = np.abs(last) > FLOAT_EPSILON
    if not parameters.allow_nonzero_velocity_at_trajectory_end and moving.any():
        k = int(np.argmax(moving))
        raise GoalRejected(
            f"Velocity of last trajectory point of joint {goal.joint_names[k]} is not "
            f"zero: {last[k]:.15f} (allow_nonzero_velocity_at_trajectory_end is false)")
    check_start_time(goal)
    tolerances, warning = goal_tolerances(parameters, goal)
    return GoalPlan(indices, spline, tolerances, warning,
                    arrays if arrays.integrates else None)


def _planned(joints: JointLimitTable, indices: np.ndarray, names: tuple[str, ...],
             arrays: GoalArrays, unwrap: bool = True) -> Spline:
    """The segments between the points, after checking them against the joints' limits."""
    order = arrays.interpolation_order()
    times, positions, velocities = arrays.times, arrays.positions, arrays.velocities
    lower, upper = joints.lower[indices], joints.upper[indices]
    limit, continuous = joints.velocity[indices], joints.continuous[indices]
    outside = ~continuous & ((positions < lower) | (positions > upper))
    if outside.any():
        p, k = first_index(outside)
        raise GoalRejected(f"point {p} joint '{names[k]}' position "
                           f"{positions[p, k]:g} is outside its limits [{lower[k]:g}, "
                           f"{upper[k]:g}]")
    too_fast = np.abs(velocities) > limit
    if too_fast.any():
        p, k = first_index(too_fast)
        raise GoalRejected(f"point {p} joint '{names[k]}' velocity "
                           f"{velocities[p, k]:g} exceeds its limit {limit[k]:g}")
    # continuous joints: each point on the turn nearest the point before (the first is
    # put on the turn nearest the joint's state when the goal starts); not a goal whose
    # points are integrated: its positions are taken as given and integrated (hil's choice)
    if unwrap:
        positions[:, continuous] = np.unwrap(positions[:, continuous], axis=0)
    if len(times) > 1:
        implied = np.diff(positions, axis=0) / np.diff(times)[:, None]
        too_fast = np.abs(implied) > limit * (1 + 1e-9)
        if too_fast.any():
            p, k = first_index(too_fast)
            raise GoalRejected(
                f"point {p + 1} joint '{names[k]}' needs {abs(implied[p, k]):.4g}"
                f" on average from point {p}, above its velocity limit {limit[k]:g}")
    return Spline.between(times, positions, velocities, arrays.accelerations, order)


def check_reachable(joints: JointLimitTable, parameters: JtcParameters, indices: np.ndarray,
                    here: np.ndarray, spline: Spline, at: float, available: float) -> None:
    """hil's own check (reject_unreachable_first_point): the joints reach the first point in
    its time (``available`` s from ``at``, the goal's clock now) within their velocity
    limits; where it is due now or past, the trajectory's position now is where they are
    (the JTC would command the jump)."""
    distance = np.abs(spline.points[0] - here)
    jump = np.abs(spline.sample(at)[0] - here)
    for k, i in enumerate(indices):
        name = joints.names[i]
        slack = parameters.constraint(name).goal or FIRST_POINT_SLACK
        if available <= 0:
            if jump[k] > slack:
                raise GoalRejected(
                    f"point 0 joint '{name}' is due {-available:.4g} s ago on the goal's "
                    f"clock and the trajectory is {jump[k]:.4g} from the current position "
                    "there: give the first point a time to get there "
                    "(reject_unreachable_first_point)")
        elif distance[k] / available > joints.velocity[i] * (1 + 1e-9):
            raise GoalRejected(
                f"point 0 joint '{name}' needs {distance[k] / available:.4g} on "
                f"average from the current position, above its velocity limit "
                f"{joints.velocity[i]:g} (reject_unreachable_first_point)")


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
