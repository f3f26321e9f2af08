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
    objects, and freeing them in one go held the control loop's thread for cycles
    (docs/performance.md, "2026-12-06, later: figures from code comments").
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
#: velocities) or quinticly (and accelerations); accelerations without velocities fit none
#: (trajectory.cpp interpolate_between_points leaves such a sample at zero), and hil guesses
#: no velocity: refused, but where the point's positions are integrated
_ACCELERATIONS_ALONE = "{} gives accelerations without velocities: give both, or neither"
_FIELDS = ("positions", "velocities", "accelerations")


@dataclass
class GivenFields:
    """Which fields each point gives (booleans, one per point)."""

    positions: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray


@dataclass
class GoalArrays:
    """A goal's points as arrays: times (points,); positions, velocities and accelerations
    (points x joints), zeros where a point gives none (``given`` says which it gave)."""

    times: np.ndarray
    positions: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray
    given: GivenFields

    @property
    def integrates(self) -> bool:
        """Whether a point leaves its positions to allow_integration_in_goal_trajectories."""
        return not bool(self.given.positions.all())

    def interpolation_order(self) -> int:
        """1, 3 or 5: linear, cubic or quintic, by what every point gives; the velocities and
        accelerations an order does not use are zeroed (linear: velocities given on some
        points only)."""
        order = (5 if self.given.accelerations.all() else
                 3 if self.given.velocities.all() else 1)
        if order < 3:
            self.velocities[:] = 0.0
        if order < 5:
            self.accelerations[:] = 0.0
        return order


def goal_arrays(goal: TrajectoryGoal, integrate: bool = False) -> GoalArrays:
    """The points as arrays, after checking their shapes, values and times as
    validate_trajectory_msg does (joint_trajectory_controller.cpp, jazzy): without
    ``integrate`` every point gives positions, and velocities and accelerations or none;
    with it (allow_integration_in_goal_trajectories) a point may leave out any of the three
    but not all, and what it gives has a value per joint."""
    names, points = goal.joint_names, goal.points
    if isinstance(points, TrajectoryPoints):
        return _arrays_given(names, points)
    n = len(names)
    for p, point in enumerate(points):
        _check_point(p, point, n, integrate)
    arrays = []
    for what in _FIELDS:
        values = np.zeros((len(points), n))
        for p, point in enumerate(points):
            given = getattr(point, what)
            if given:
                values[p] = given
        arrays.append(values)
    given = GivenFields(*(np.array([bool(getattr(point, what)) for point in points])
                          for what in _FIELDS))
    times = np.array([point.time_from_start for point in points], dtype=float)
    return _checked(names, GoalArrays(times, *arrays, given))


def _check_point(p: int, point: TrajectoryPoint, n: int, integrate: bool) -> None:
    """GoalRejected for a point validate_trajectory_msg refuses (and hil's accelerations
    without velocities)."""
    if integrate and not (point.positions or point.velocities or point.accelerations):
        raise GoalRejected(f"point {p} gives no positions, velocities or accelerations (\"The "
                           "given trajectory has no position, velocity, or acceleration "
                           "points.\")")
    if point.accelerations and not point.velocities and point.positions:
        raise GoalRejected(_ACCELERATIONS_ALONE.format(f"point {p}"))
    if not integrate and len(point.positions) != n:
        hint = ("; a point without positions needs allow_integration_in_goal_trajectories"
                if not point.positions else "")
        raise GoalRejected(f"point {p} has {len(point.positions)} positions for {n} "
                           f"joints{hint}")
    for what in _FIELDS:
        values = getattr(point, what)
        if values and len(values) != n:
            raise GoalRejected(f"point {p} has {len(values)} {what} for {n} joints")


def _arrays_given(names: tuple[str, ...], points: TrajectoryPoints) -> GoalArrays:
    """:func:`goal_arrays` of points that are arrays already (each gives positions)."""
    n = len(names)
    shaped = lambda values: values is not None and values.shape == (len(points), n)  # noqa: E731
    for what, values in (("positions", points.positions), ("velocities", points.velocities),
                         ("accelerations", points.accelerations)):
        if values is not None and not shaped(values):
            raise GoalRejected(f"the goal's {what} are {' x '.join(map(str, values.shape))}"
                               f" for {len(points)} points of {n} joints")
    if points.accelerations is not None and points.velocities is None:
        raise GoalRejected(_ACCELERATIONS_ALONE.format("the goal"))
    copied = lambda values: (values.copy() if values is not None  # noqa: E731
                             else np.zeros((len(points), n)))
    every = lambda condition: np.full(len(points), condition)  # noqa: E731
    given = GivenFields(every(True), every(points.velocities is not None),
                        every(points.accelerations is not None))
    return _checked(names, GoalArrays(points.times.copy(), points.positions.copy(),
                                      copied(points.velocities), copied(points.accelerations),
                                      given))


def _checked(names, arrays: GoalArrays) -> GoalArrays:
    """The arrays after checking their values and times."""
    for values, singular in ((arrays.positions, "position"), (arrays.velocities, "velocity"),
                             (arrays.accelerations, "acceleration")):
        bad = ~np.isfinite(values)
        if bad.any():
            p, k = first_index(bad)
            raise GoalRejected(f"point {p} joint '{names[k]}' {singular} is "
                               f"{values[p, k]}")
    times = arrays.times
    previous = np.concatenate(([-math.inf], times[:-1]))
    bad = ~np.isfinite(times) | (times <= previous) | (times < 0)
    if bad.any():
        p = int(np.argmax(bad))
        raise GoalRejected(f"point {p} time_from_start {times[p]} is not after the "
                           "previous point's (times must increase, from >= 0)")
    return arrays


def first_index(mask: np.ndarray) -> tuple[int, int]:
    """(point, joint) of the first True in a points x joints mask."""
    point, joint = np.argwhere(mask)[0]
    return int(point), int(joint)
