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

import threading
from dataclasses import dataclass, field

import numpy as np

from hil.controllers.goal import (
    GOAL_TOLERANCE_VIOLATED, HARDWARE_FAULT, INVALID_GOAL, INVALID_JOINTS, MAX_POINTS,
    PATH_TOLERANCE_VIOLATED, SUCCESSFUL, Defaults, GoalRejected, GoalResult, GoalStatus,
    JointTolerance, TrajectoryGoal, check_tolerances, first_index, goal_arrays,
)
from hil.controllers.spline import Spline
from hil.description import JointType, RobotDescription


@dataclass
class _ActiveGoal:
    goal_id: str
    indices: np.ndarray            # controller joint index of each goal joint
    spline: Spline                 # on the goal's clock: 0 = start
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
class _Plan:
    """A goal checked and planned between its points, before it meets the controller's
    state (made without the lock)."""

    indices: np.ndarray
    spline: Spline
    path: tuple[np.ndarray, np.ndarray]
    tolerance: tuple[np.ndarray, np.ndarray]
    goal_time_tolerance: float


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
        """Validate and start a goal, preempting the active one; raises GoalRejected.

        The goal is checked and planned without the controller's lock (a 10,000-point goal
        takes milliseconds): the control cycle waits only for the first segment, planned
        from its state under the lock."""
        with self._lock:
            self._check_accepting()
        plan = self._plan(goal)
        with self._lock:
            self._check_accepting()
            active = self._start(goal_id, goal, plan)
            if self._active is not None and self._active.result is None:
                self._finish(self._active, GoalResult(
                    GoalStatus.ABORTED, INVALID_GOAL,
                    f"preempted by goal {goal_id}"))
            self._active = active

    def _check_accepting(self) -> None:
        if self._fault is not None:
            raise GoalRejected(f"the hardware is faulted: {self._fault}", HARDWARE_FAULT)
        if not self._initialised:
            raise GoalRejected("the controller has no joint state yet (hardware starting)",
                               HARDWARE_FAULT)

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
            p, v, a = goal.spline.sample(now - goal.start)
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

    def _plan(self, goal: TrajectoryGoal) -> _Plan:
        """Check a goal and plan its segments between points (no lock held: it reads only the
        controller's fixed limits)."""
        indices = self._check_joints(goal)
        if not goal.points:
            raise GoalRejected("the trajectory has no points")
        if len(goal.points) > MAX_POINTS:
            raise GoalRejected(f"the trajectory has {len(goal.points)} points; this controller "
                               f"takes at most {MAX_POINTS} (split it into several goals, or "
                               "sample it more coarsely)")
        times, positions, velocities, accelerations, order = goal_arrays(goal)
        lower, upper = self._lower[indices], self._upper[indices]
        limit, continuous = self._velocity_limit[indices], self._continuous[indices]
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
        path = self._tolerances(goal.path_tolerance, goal.joint_names,
                                self.defaults.path_position_tolerance, 0.0)
        tolerance = self._tolerances(goal.goal_tolerance, goal.joint_names,
                                     self.defaults.goal_position_tolerance,
                                     self.defaults.goal_velocity_tolerance)
        goal_time = (goal.goal_time_tolerance if goal.goal_time_tolerance > 0 else
                     self.defaults.goal_time_tolerance)
        return _Plan(indices, Spline.between(times, positions, velocities, accelerations, order),
                     path, tolerance, goal_time)

    def _check_joints(self, goal: TrajectoryGoal) -> np.ndarray:
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
        return np.array([self.joint_names.index(n) for n in names])

    def _start(self, goal_id: str, goal: TrajectoryGoal, plan: _Plan) -> _ActiveGoal:
        """The planned goal from the controller's state now (lock held): continuous joints on
        the turn nearest where they are, the first point reachable at the velocity limits,
        the first segment from the desired state."""
        indices, spline = plan.indices, plan.spline
        start = self._now if goal.start_time is None else max(goal.start_time, self._now)
        here = self._desired[indices].copy()
        turns = np.round((spline.points[0] - here) / (2 * np.pi))
        spline.shift(np.where(self._continuous[indices], -turns * 2 * np.pi, 0.0))
        self._check_reachable(goal, indices, here, spline.points[0])
        spline.start_from(here, self._desired_velocity[indices].copy(),
                          self._desired_acceleration[indices].copy())
        return _ActiveGoal(goal_id, indices, spline, start, start + spline.end, *plan.path,
                           *plan.tolerance, plan.goal_time_tolerance, spline.points[-1].copy())

    def _check_reachable(self, goal: TrajectoryGoal, indices: np.ndarray, here: np.ndarray,
                         first: np.ndarray) -> None:
        """The move from where the joints are to the first point must respect the limits."""
        distance = np.abs(first - here)
        first_time = goal.points[0].time_from_start
        for k, i in enumerate(indices):
            name = self.joint_names[i]
            if first_time == 0:
                if distance[k] > self.defaults.goal_position_tolerance:
                    raise GoalRejected(
                        f"point 0 joint '{name}' is {distance[k]:.4g} from the current position "
                        "at time_from_start 0: give the first point a time to get there")
            elif distance[k] / first_time > self._velocity_limit[i] * (1 + 1e-9):
                raise GoalRejected(
                    f"point 0 joint '{name}' needs {distance[k] / first_time:.4g} on "
                    f"average from the current position, above its velocity limit "
                    f"{self._velocity_limit[i]:g}")

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
