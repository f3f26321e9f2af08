"""A FollowJointTrajectory goal as the controller takes it: points, tolerances, and the
result and status it ends with (control_msgs' error codes, action_msgs' status numbers)."""

from __future__ import annotations

import enum
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

# control_msgs/FollowJointTrajectory result error codes, and hil's one extension.
SUCCESSFUL = 0
INVALID_GOAL = -1
INVALID_JOINTS = -2
PATH_TOLERANCE_VIOLATED = -4
GOAL_TOLERANCE_VIOLATED = -5
HARDWARE_FAULT = -100        # hil: a drive faulted or went silent (not in control_msgs)

#: the most points a goal may have: planned, a point takes 6 coefficients per joint and
#: segment (100,000 points of 6 joints: 29 MB)
MAX_POINTS = 100_000


#: the JTC's result strings (joint_trajectory_controller.cpp, jazzy): clients may compare them
REACHED = "Goal successfully reached!"
PREEMPTED = "Current goal preempted by new incoming action."
PATH_ABORT = "Aborted due to path tolerance violation"
GOAL_TIME_ABORT = "Aborted due to goal_time_tolerance exceeding by {:.6f} seconds"
DEACTIVATED = "Current goal cancelled during deactivate transition."


class GoalStatus(enum.Enum):
    """Terminal states of a goal, as action_msgs/GoalStatus numbers them."""

    SUCCEEDED = 4
    CANCELED = 5
    ABORTED = 6
    REJECTED = 7       # not an action_msgs status: the goal never became active


@dataclass(frozen=True)
class TrajectoryPoint:
    time_from_start: float
    positions: tuple[float, ...]
    velocities: tuple[float, ...] = ()
    accelerations: tuple[float, ...] = ()


class TrajectoryPoints(Sequence[TrajectoryPoint]):
    """A goal's points held as arrays, as a decoded message gives them: ``times`` (points,),
    ``positions`` (points x joints), ``velocities`` and ``accelerations`` the same or None.

    A sequence of :class:`TrajectoryPoint` to whoever reads it point by point; the controller
    takes the arrays as they are. Why: a 10,000-point goal as objects is about 100,000 Python
    objects, and freeing them in one go held the control loop's thread for 5 ms (measured).
    """

    def __init__(self, times: np.ndarray, positions: np.ndarray,
                 velocities: np.ndarray | None = None, accelerations: np.ndarray | None = None):
        self.times = np.asarray(times, dtype=float)
        self.positions = np.asarray(positions, dtype=float)
        self.velocities = velocities
        self.accelerations = accelerations

    def __len__(self) -> int:
        return len(self.times)

    def __getitem__(self, index):
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(len(self)))]
        optional = lambda values: () if values is None else tuple(values[index].tolist())  # noqa: E731
        return TrajectoryPoint(float(self.times[index]), tuple(self.positions[index].tolist()),
                               optional(self.velocities), optional(self.accelerations))


@dataclass(frozen=True)
class JointTolerance:
    name: str
    position: float = 0.0
    velocity: float = 0.0


@dataclass(frozen=True)
class TrajectoryGoal:
    """A FollowJointTrajectory goal. ``start_time`` is on the controller's clock; None = now."""

    joint_names: tuple[str, ...]
    points: Sequence[TrajectoryPoint]       # a tuple, or TrajectoryPoints
    start_time: float | None = None
    path_tolerance: tuple[JointTolerance, ...] = ()
    goal_tolerance: tuple[JointTolerance, ...] = ()
    #: control_msgs: 0 keeps the controller's constraints.goal_time, -1 erases it (no time
    #: limit), > 0 replaces it
    goal_time_tolerance: float = 0.0
    #: whether any point carries efforts (the JTC refuses them without an effort command
    #: interface, which hil's hardware does not export)
    has_efforts: bool = False


@dataclass(frozen=True)
class GoalResult:
    status: GoalStatus
    error_code: int
    error_string: str = ""


class GoalRejected(ValueError):
    def __init__(self, reason: str, error_code: int = INVALID_GOAL):
        super().__init__(reason)
        self.error_code = error_code


def check_start_time(goal: TrajectoryGoal) -> None:
    """Raise GoalRejected for a start time that is not a finite value."""
    if goal.start_time is not None and not math.isfinite(goal.start_time):
        raise GoalRejected(f"the start time {goal.start_time} is not a time")

#: ros2_controllers' trajectory interpolates linearly (positions), cubically (and
#: velocities) or quinticly (and accelerations); accelerations without velocities fit none,
#: and hil guesses no velocity: refused
_ACCELERATIONS_ALONE = "{} gives accelerations without velocities: give both, or neither"


def goal_arrays(goal: TrajectoryGoal):
    """The points as arrays (times; positions, velocities, accelerations: points x
    joints, zeros where the order does not use them) and the interpolation order, after
    checking their shapes, values and times."""
    names, points = goal.joint_names, goal.points
    n = len(names)
    if isinstance(points, TrajectoryPoints):
        return _arrays_given(names, points)
    for p, point in enumerate(points):
        if point.accelerations and not point.velocities:
            raise GoalRejected(_ACCELERATIONS_ALONE.format(f"point {p}"))
        if len(point.positions) != n:
            raise GoalRejected(f"point {p} has {len(point.positions)} positions for "
                               f"{n} joints")
        for what in ("velocities", "accelerations"):
            values = getattr(point, what)
            if values and len(values) != n:
                raise GoalRejected(f"point {p} has {len(values)} {what} for {n} joints")
    order = (5 if all(p.accelerations for p in points) else
             3 if all(p.velocities for p in points) else 1)
    arrays = []
    for what in ("positions", "velocities", "accelerations"):
        values = np.zeros((len(points), n))
        for p, point in enumerate(points):
            given = getattr(point, what)
            if given:
                values[p] = given
        arrays.append(values)
    times = np.array([point.time_from_start for point in points], dtype=float)
    return _checked(names, times, *arrays, order)

def _arrays_given(names: tuple[str, ...], points: TrajectoryPoints):
    """:func:`goal_arrays` of points that are arrays already."""
    n = len(names)
    shaped = lambda values: values is not None and values.shape == (len(points), n)  # noqa: E731
    for what, values in (("positions", points.positions), ("velocities", points.velocities),
                         ("accelerations", points.accelerations)):
        if values is not None and not shaped(values):
            raise GoalRejected(f"the goal's {what} are {' x '.join(map(str, values.shape))}"
                               f" for {len(points)} points of {n} joints")
    if points.accelerations is not None and points.velocities is None:
        raise GoalRejected(_ACCELERATIONS_ALONE.format("the goal"))
    order = (5 if shaped(points.accelerations) else 3 if shaped(points.velocities) else 1)
    zeros = np.zeros((len(points), n))
    return _checked(
        names, points.times.copy(), points.positions.copy(),
        points.velocities.copy() if order >= 3 else zeros,
        points.accelerations.copy() if order == 5 else zeros.copy(), order)

def _checked(names, times, positions, velocities, accelerations, order):
    """The arrays after checking their values and times; velocities and accelerations
    zeroed where the order does not use them."""
    for values, singular in ((positions, "position"), (velocities, "velocity"),
                             (accelerations, "acceleration")):
        bad = ~np.isfinite(values)
        if bad.any():
            p, k = first_index(bad)
            raise GoalRejected(f"point {p} joint '{names[k]}' {singular} is "
                               f"{values[p, k]}")
    if order < 3:
        velocities[:] = 0.0            # linear: velocities given on some points only
    if order < 5:
        accelerations[:] = 0.0
    previous = np.concatenate(([-math.inf], times[:-1]))
    bad = ~np.isfinite(times) | (times <= previous) | (times < 0)
    if bad.any():
        p = int(np.argmax(bad))
        raise GoalRejected(f"point {p} time_from_start {times[p]} is not after the "
                           "previous point's (times must increase, from >= 0)")
    return times, positions, velocities, accelerations, order


def first_index(mask: np.ndarray) -> tuple[int, int]:
    """(point, joint) of the first True in a points x joints mask."""
    point, joint = np.argwhere(mask)[0]
    return int(point), int(joint)
