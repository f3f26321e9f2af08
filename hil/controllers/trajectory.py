"""Joint trajectory controller, with ros2_controllers' joint_trajectory_controller semantics.

* A goal is validated before any motion: unknown, duplicate or mimic joints,
  ragged or non-finite points, non-increasing ``time_from_start``, positions
  outside the joint limits, velocities (given, or implied by consecutive
  points) above the velocity limits: each rejection names the joint and point.
* Interpolation follows what the points give: positions only -> linear,
  + velocities -> cubic, + accelerations -> quintic; the first segment starts
  from the current desired state (or the measured one when idle).
* A trajectory may start in the future (it holds until then); a goal may name
  a subset of the joints (the others hold); a new goal preempts the active one,
  which is aborted with the reason; cancel holds the current position.
* Path tolerances are checked while executing, goal tolerances at the end
  within ``goal_time_tolerance``; a tolerance of 0 takes the controller's
  default and a negative one disables the check (as in control_msgs).
* Continuous joints: goal positions are unwrapped to the nearest turn and
  errors are the shortest angle.
"""

from __future__ import annotations

import enum
import math
import threading
from dataclasses import dataclass, field

import numpy as np

from hil.description import JointType, RobotDescription

# control_msgs/FollowJointTrajectory result error codes, and hil's one extension.
SUCCESSFUL = 0
INVALID_GOAL = -1
INVALID_JOINTS = -2
PATH_TOLERANCE_VIOLATED = -4
GOAL_TOLERANCE_VIOLATED = -5
HARDWARE_FAULT = -100        # hil: a drive faulted or went silent (not in control_msgs)


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


@dataclass(frozen=True)
class JointTolerance:
    name: str
    position: float = 0.0
    velocity: float = 0.0


@dataclass(frozen=True)
class TrajectoryGoal:
    """A FollowJointTrajectory goal. ``start_time`` is on the controller's clock; None = now."""

    joint_names: tuple[str, ...]
    points: tuple[TrajectoryPoint, ...]
    start_time: float | None = None
    path_tolerance: tuple[JointTolerance, ...] = ()
    goal_tolerance: tuple[JointTolerance, ...] = ()
    goal_time_tolerance: float = 0.0


@dataclass(frozen=True)
class GoalResult:
    status: GoalStatus
    error_code: int
    error_string: str = ""


@dataclass(frozen=True)
class Defaults:
    """Controller defaults for what a goal leaves at 0."""

    goal_position_tolerance: float = 0.02
    goal_velocity_tolerance: float = 0.0        # 0: not checked
    path_position_tolerance: float = 0.0        # 0: not checked
    goal_time_tolerance: float = 1.0
    stopped_velocity_tolerance: float = 0.05


class GoalRejected(ValueError):
    def __init__(self, reason: str, error_code: int = INVALID_GOAL):
        super().__init__(reason)
        self.error_code = error_code


@dataclass
class _Segment:
    """Polynomial p(t) = sum c_k (t - t0)^k per joint on [t0, t1]."""

    t0: float
    t1: float
    coefficients: np.ndarray      # (6, joints)

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        tau = min(max(t - self.t0, 0.0), self.t1 - self.t0)
        c = self.coefficients
        powers = tau ** np.arange(6)
        position = powers @ c
        velocity = (np.arange(1, 6) * powers[:5]) @ c[1:]
        acceleration = (np.array([2, 6, 12, 20]) * powers[:4]) @ c[2:]
        return position, velocity, acceleration


def _segment(t0, t1, p0, v0, a0, p1, v1, a1, order: int) -> _Segment:
    """Linear (order 1), cubic (3) or quintic (5) segment between two states."""
    T = t1 - t0
    c = np.zeros((6, len(p0)))
    if order == 1:
        c[0], c[1] = p0, (p1 - p0) / T
    elif order == 3:
        c[0], c[1] = p0, v0
        c[2] = (3 * (p1 - p0) - (2 * v0 + v1) * T) / T ** 2
        c[3] = (2 * (p0 - p1) + (v0 + v1) * T) / T ** 3
    else:
        c[0], c[1], c[2] = p0, v0, a0 / 2
        c[3] = (20 * (p1 - p0) - (8 * v1 + 12 * v0) * T - (3 * a0 - a1) * T ** 2) / (2 * T ** 3)
        c[4] = (30 * (p0 - p1) + (14 * v1 + 16 * v0) * T + (3 * a0 - 2 * a1) * T ** 2) / (2 * T ** 4)
        c[5] = (12 * (p1 - p0) - (6 * v1 + 6 * v0) * T - (a0 - a1) * T ** 2) / (2 * T ** 5)
    return _Segment(t0, t1, c)


@dataclass
class _ActiveGoal:
    goal_id: str
    indices: np.ndarray            # controller joint index of each goal joint
    segments: list[_Segment]
    start: float
    end: float
    path_position: np.ndarray
    path_velocity: np.ndarray
    goal_position: np.ndarray
    goal_velocity: np.ndarray
    goal_time_tolerance: float
    final: np.ndarray
    result: GoalResult | None = None


@dataclass
class ControllerState:
    """What the controller reports each cycle (control_msgs feedback fields)."""

    time: float
    joint_names: tuple[str, ...]
    desired_positions: np.ndarray
    desired_velocities: np.ndarray
    actual_positions: np.ndarray
    actual_velocities: np.ndarray
    goal_id: str | None
    errors: np.ndarray = field(init=False)

    def __post_init__(self):
        self.errors = self.desired_positions - self.actual_positions


class JointTrajectoryController:
    """Position-commanding trajectory controller over a robot's actuated joints.

    Thread-safe: goals and cancels may arrive from any thread; :meth:`update`
    runs in the control loop.
    """

    def __init__(self, robot: RobotDescription, defaults: Defaults = Defaults()):
        self.joints = tuple(j for j in robot.driven_joints)
        self.joint_names = tuple(j.name for j in self.joints)
        self.defaults = defaults
        self._mimic = {j.name: j.mimic.joint for j in robot.joints if j.mimic}
        self._continuous = np.array([j.type is JointType.CONTINUOUS for j in self.joints])
        self._lower = np.array([j.limits.lower if j.limits and j.limits.lower is not None
                                else -np.inf for j in self.joints])
        self._upper = np.array([j.limits.upper if j.limits and j.limits.upper is not None
                                else np.inf for j in self.joints])
        self._velocity_limit = np.array([j.limits.velocity if j.limits else np.inf
                                         for j in self.joints])
        n = len(self.joints)
        self._lock = threading.Lock()
        self._active: _ActiveGoal | None = None
        self._finished: list[tuple[str, GoalResult]] = []
        self._desired = np.zeros(n)
        self._desired_velocity = np.zeros(n)
        self._desired_acceleration = np.zeros(n)
        self._initialised = False
        self._actual = np.zeros(n)
        self._actual_velocity = np.zeros(n)
        self._now = 0.0
        self._fault: str | None = None

    # --- goals ------------------------------------------------------------------

    def submit(self, goal_id: str, goal: TrajectoryGoal) -> None:
        """Validate and start a goal, preempting the active one; raises GoalRejected."""
        with self._lock:
            if self._fault is not None:
                raise GoalRejected(f"the hardware is faulted: {self._fault}", HARDWARE_FAULT)
            if not self._initialised:
                raise GoalRejected("the controller has no joint state yet (hardware starting)",
                                   HARDWARE_FAULT)
            indices = self._validate(goal)
            active = self._plan(goal_id, goal, indices)
            if self._active is not None and self._active.result is None:
                self._finish(self._active, GoalResult(
                    GoalStatus.ABORTED, INVALID_GOAL,
                    f"preempted by goal {goal_id}"))
            self._active = active

    def cancel(self, goal_id: str) -> bool:
        """Cancel a goal: the joints hold where they are. False if it is not active."""
        with self._lock:
            if self._active is None or self._active.goal_id != goal_id or self._active.result:
                return False
            self._hold_actual()
            self._finish(self._active, GoalResult(GoalStatus.CANCELED, SUCCESSFUL,
                                                  "canceled: holding position"))
            return True

    def abort(self, reason: str, error_code: int = HARDWARE_FAULT) -> None:
        """A hardware fault: abort the active goal, hold, refuse goals until :meth:`clear_fault`."""
        with self._lock:
            self._fault = reason
            self._hold_actual()
            if self._active is not None and self._active.result is None:
                self._finish(self._active, GoalResult(GoalStatus.ABORTED, error_code, reason))

    @property
    def fault(self) -> str | None:
        """Why goals are refused (a hardware fault), or None."""
        with self._lock:
            return self._fault

    def clear_fault(self) -> None:
        """Accept goals again, holding the joints where they are now."""
        with self._lock:
            self._fault = None
            self._hold_actual()

    def finished(self) -> list[tuple[str, GoalResult]]:
        """Results of goals that ended since the last call."""
        with self._lock:
            done, self._finished = self._finished, []
            return done

    @property
    def active_goal(self) -> str | None:
        with self._lock:
            return self._active.goal_id if self._active and not self._active.result else None

    # --- the control cycle ---------------------------------------------------------

    def update(self, now: float, positions: np.ndarray, velocities: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
        """One cycle: measured joint state in, position and velocity commands out."""
        with self._lock:
            self._now = now
            self._actual, self._actual_velocity = positions, velocities
            if not self._initialised:
                self._hold_actual()
                self._initialised = True
            goal = self._active
            if goal is not None and goal.result is None:
                self._follow(goal, now)
            return self._desired.copy(), self._desired_velocity.copy()

    def state(self) -> ControllerState:
        with self._lock:
            return ControllerState(
                self._now, self.joint_names, self._desired.copy(), self._desired_velocity.copy(),
                self._actual.copy(), self._actual_velocity.copy(),
                self._active.goal_id if self._active and not self._active.result else None)

    # --- internals (lock held) ----------------------------------------------------

    def _follow(self, goal: _ActiveGoal, now: float) -> None:
        idx = goal.indices
        if now >= goal.start:
            segment = next((s for s in goal.segments if now <= s.t1), goal.segments[-1])
            p, v, a = segment.sample(now)
            self._desired[idx], self._desired_velocity[idx] = p, v
            self._desired_acceleration[idx] = a
        error = self._wrap(self._desired[idx] - self._actual[idx], idx)
        if goal.start <= now <= goal.end:
            self._check_path(goal, error)
        if now >= goal.end and goal.result is None:
            self._desired_velocity[idx] = 0.0
            self._desired_acceleration[idx] = 0.0
            self._check_goal(goal, now)

    def _check_path(self, goal: _ActiveGoal, error: np.ndarray) -> None:
        velocity_error = self._desired_velocity[goal.indices] - self._actual_velocity[goal.indices]
        for k, i in enumerate(goal.indices):
            for what, value, tolerance in (("position", error[k], goal.path_position[k]),
                                           ("velocity", velocity_error[k], goal.path_velocity[k])):
                if tolerance > 0 and abs(value) > tolerance:
                    self._hold_actual()
                    self._finish(goal, GoalResult(
                        GoalStatus.ABORTED, PATH_TOLERANCE_VIOLATED,
                        f"joint '{self.joint_names[i]}' {what} error {value:+.4f} exceeds the "
                        f"path tolerance {tolerance:g} at t={self._now - goal.start:.3f} s"))
                    return

    def _check_goal(self, goal: _ActiveGoal, now: float) -> None:
        idx = goal.indices
        error = np.abs(self._wrap(goal.final - self._actual[idx], idx))
        velocity = np.abs(self._actual_velocity[idx])
        position_ok = (goal.goal_position <= 0) | (error <= goal.goal_position)
        velocity_ok = (goal.goal_velocity <= 0) | (velocity <= goal.goal_velocity)
        if np.all(position_ok & velocity_ok):
            self._finish(goal, GoalResult(GoalStatus.SUCCEEDED, SUCCESSFUL))
        elif now > goal.end + goal.goal_time_tolerance:
            k = int(np.argmax(~(position_ok & velocity_ok)))
            self._finish(goal, GoalResult(
                GoalStatus.ABORTED, GOAL_TOLERANCE_VIOLATED,
                f"joint '{self.joint_names[idx[k]]}' is {error[k]:.4f} from its goal "
                f"(tolerance {goal.goal_position[k]:g}), velocity {velocity[k]:.4f}, "
                f"{now - goal.end:.3f} s after the trajectory ended (goal_time_tolerance "
                f"{goal.goal_time_tolerance:g} s)"))

    def _finish(self, goal: _ActiveGoal, result: GoalResult) -> None:
        goal.result = result
        self._finished.append((goal.goal_id, result))

    def _hold_actual(self) -> None:
        self._desired = self._actual.copy()
        self._desired_velocity = np.zeros_like(self._desired)
        self._desired_acceleration = np.zeros_like(self._desired)

    def _wrap(self, difference: np.ndarray, indices: np.ndarray) -> np.ndarray:
        wrapped = (difference + np.pi) % (2 * np.pi) - np.pi
        return np.where(self._continuous[indices], wrapped, difference)

    def _validate(self, goal: TrajectoryGoal) -> np.ndarray:
        names = goal.joint_names
        if not names:
            raise GoalRejected("the goal names no joints", INVALID_JOINTS)
        for name in names:
            if name in self._mimic:
                raise GoalRejected(f"joint '{name}' mimics '{self._mimic[name]}' and cannot be "
                                   "commanded; command its leader", INVALID_JOINTS)
            if name not in self.joint_names:
                raise GoalRejected(f"unknown joint '{name}'; this controller has: "
                                   f"{', '.join(self.joint_names)}", INVALID_JOINTS)
        if len(set(names)) != len(names):
            raise GoalRejected("a joint is named twice in the goal", INVALID_JOINTS)
        if not goal.points:
            raise GoalRejected("the trajectory has no points")
        indices = np.array([self.joint_names.index(n) for n in names])
        previous_time = -math.inf
        for p, point in enumerate(goal.points):
            where = f"point {p}"
            if len(point.positions) != len(names):
                raise GoalRejected(f"{where} has {len(point.positions)} positions for "
                                   f"{len(names)} joints")
            for field_name in ("velocities", "accelerations"):
                values = getattr(point, field_name)
                if values and len(values) != len(names):
                    raise GoalRejected(f"{where} has {len(values)} {field_name} for "
                                       f"{len(names)} joints")
            for field_name in ("positions", "velocities", "accelerations"):
                for k, value in enumerate(getattr(point, field_name)):
                    if not math.isfinite(value):
                        raise GoalRejected(f"{where} joint '{names[k]}' {field_name[:-1]} is "
                                           f"{value}")
            if not math.isfinite(point.time_from_start) or point.time_from_start <= previous_time \
                    or point.time_from_start < 0:
                raise GoalRejected(f"{where} time_from_start {point.time_from_start} is not "
                                   "after the previous point's (times must increase, from >= 0)")
            previous_time = point.time_from_start
            for k, i in enumerate(indices):
                q = point.positions[k]
                if not self._continuous[i] and not self._lower[i] <= q <= self._upper[i]:
                    raise GoalRejected(f"{where} joint '{names[k]}' position {q:g} is outside "
                                       f"its limits [{self._lower[i]:g}, {self._upper[i]:g}]")
                if point.velocities and abs(point.velocities[k]) > self._velocity_limit[i]:
                    raise GoalRejected(f"{where} joint '{names[k]}' velocity "
                                       f"{point.velocities[k]:g} exceeds its limit "
                                       f"{self._velocity_limit[i]:g}")
        for p in range(1, len(goal.points)):
            a, b = goal.points[p - 1], goal.points[p]
            implied = (np.array(b.positions) - np.array(a.positions)) / (b.time_from_start
                                                                           - a.time_from_start)
            too_fast = np.abs(implied) > self._velocity_limit[indices] * (1 + 1e-9)
            if too_fast.any():
                k = int(np.argmax(too_fast))
                raise GoalRejected(
                    f"point {p} joint '{names[k]}' needs {abs(implied[k]):.4g} on average from "
                    f"point {p - 1}, above its velocity limit {self._velocity_limit[indices[k]]:g}")
        for tolerance in (*goal.path_tolerance, *goal.goal_tolerance):
            if tolerance.name not in names:
                raise GoalRejected(f"tolerance for joint '{tolerance.name}', which the goal does "
                                   "not command", INVALID_JOINTS)
        return indices

    def _plan(self, goal_id: str, goal: TrajectoryGoal, indices: np.ndarray) -> _ActiveGoal:
        start = self._now if goal.start_time is None else max(goal.start_time, self._now)
        p0 = self._desired[indices].copy()
        v0 = self._desired_velocity[indices].copy()
        a0 = self._desired_acceleration[indices].copy()
        order = (5 if all(p.accelerations for p in goal.points) else
                 3 if all(p.velocities for p in goal.points) else 1)
        if order == 1:
            v0 = np.zeros_like(v0)
        self._check_reachable(goal, indices, p0)
        segments, t0, previous = [], start, p0
        for point in goal.points:
            p1 = self._unwrap(np.array(point.positions, dtype=float), previous, indices)
            v1 = np.array(point.velocities or np.zeros(len(indices)), dtype=float)
            a1 = np.array(point.accelerations or np.zeros(len(indices)), dtype=float)
            t1 = start + point.time_from_start
            if t1 > t0:
                segments.append(_segment(t0, t1, p0, v0, a0, p1, v1, a1, order))
            else:      # a first point at time 0 where the joints already are
                segments.append(_segment(t0, t0 + 1e-9, p1, v1, a1, p1, v1, a1, 1))
            t0, p0, v0, a0, previous = t1, p1, v1, a1, p1
        path_p, path_v = self._tolerances(goal.path_tolerance, goal.joint_names,
                                          self.defaults.path_position_tolerance, 0.0)
        goal_p, goal_v = self._tolerances(goal.goal_tolerance, goal.joint_names,
                                          self.defaults.goal_position_tolerance,
                                          self.defaults.goal_velocity_tolerance)
        goal_time = (goal.goal_time_tolerance if goal.goal_time_tolerance > 0 else
                     self.defaults.goal_time_tolerance)
        return _ActiveGoal(goal_id, indices, segments, start, t0, path_p, path_v, goal_p,
                           goal_v, goal_time, p0)

    def _check_reachable(self, goal: TrajectoryGoal, indices: np.ndarray, here: np.ndarray) -> None:
        """The move from where the joints are to the first point must respect the limits."""
        first = goal.points[0]
        distance = np.abs(self._wrap(np.array(first.positions) - here, indices))
        for k, i in enumerate(indices):
            name = self.joint_names[i]
            if first.time_from_start == 0:
                if distance[k] > self.defaults.goal_position_tolerance:
                    raise GoalRejected(
                        f"point 0 joint '{name}' is {distance[k]:.4g} from the current position "
                        "at time_from_start 0: give the first point a time to get there")
            elif distance[k] / first.time_from_start > self._velocity_limit[i] * (1 + 1e-9):
                raise GoalRejected(
                    f"point 0 joint '{name}' needs {distance[k] / first.time_from_start:.4g} on "
                    f"average from the current position, above its velocity limit "
                    f"{self._velocity_limit[i]:g}")

    def _unwrap(self, positions: np.ndarray, reference: np.ndarray, indices: np.ndarray):
        turns = np.round((positions - reference) / (2 * np.pi))
        return np.where(self._continuous[indices], positions - turns * 2 * np.pi, positions)

    @staticmethod
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
