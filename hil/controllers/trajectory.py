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

import math
import threading
from dataclasses import dataclass, field, replace

import numpy as np

from hil.controllers.goal import (
    GOAL_TOLERANCE_VIOLATED, HARDWARE_FAULT, INVALID_GOAL, PATH_TOLERANCE_VIOLATED, SUCCESSFUL,
    Defaults, GoalRejected, GoalResult, GoalStatus, TrajectoryGoal,
)
from hil.controllers.planning import GoalPlan, JointLimitTable, plan_goal
from hil.controllers.spline import Spline
from hil.description import RobotDescription


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
class ControllerState:
    """What the controller reports each cycle (control_msgs feedback fields)."""

    time: float
    joint_names: tuple[str, ...]
    desired_positions: np.ndarray
    desired_velocities: np.ndarray
    actual_positions: np.ndarray
    actual_velocities: np.ndarray
    goal_id: str | None
    #: the trajectory point the active goal moves to now (control_msgs 6's feedback
    #: ``index``: "the currently used point"); 0 before it starts and without a goal
    point_index: int = 0
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
        self.limits = JointLimitTable.of(robot, self.joints)
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

    def set_defaults(self, **changes: float) -> None:
        """Change :class:`Defaults` fields for the goals accepted from now on (the active
        goal keeps the ones it was planned with); ValueError, changing nothing, for an
        unknown field or a value that is not a finite number >= 0. Any thread."""
        known = Defaults.__dataclass_fields__
        for name, value in changes.items():
            if name not in known:
                raise ValueError(f"no controller default '{name}'; there are: "
                                 f"{', '.join(known)}")
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"{name} must be a finite number >= 0, not {value!r}")
        self.defaults = replace(self.defaults, **changes)

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
            goal = self._active if self._active and not self._active.result else None
            return ControllerState(
                self._now, self.joint_names, self._desired.copy(), self._desired_velocity.copy(),
                self._actual.copy(), self._actual_velocity.copy(),
                goal.goal_id if goal else None,
                goal.spline.segment_at(self._now - goal.start) if goal else 0)

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
        return np.where(self.limits.continuous[indices], wrapped, difference)

    def _plan(self, goal: TrajectoryGoal) -> GoalPlan:
        """:func:`plan_goal` on this controller's joints (no lock held: it reads only their
        fixed limits)."""
        return plan_goal(self.limits, self.defaults, goal)

    def _start(self, goal_id: str, goal: TrajectoryGoal, plan: GoalPlan) -> _ActiveGoal:
        """The planned goal from the controller's state now (lock held): continuous joints on
        the turn nearest where they are, the first point reachable at the velocity limits,
        the first segment from the desired state."""
        indices, spline = plan.indices, plan.spline
        start = self._now if goal.start_time is None else max(goal.start_time, self._now)
        here = self._desired[indices].copy()
        turns = np.round((spline.points[0] - here) / (2 * np.pi))
        spline.shift(np.where(self.limits.continuous[indices], -turns * 2 * np.pi, 0.0))
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
            elif distance[k] / first_time > self.limits.velocity[i] * (1 + 1e-9):
                raise GoalRejected(
                    f"point 0 joint '{name}' needs {distance[k] / first_time:.4g} on "
                    f"average from the current position, above its velocity limit "
                    f"{self.limits.velocity[i]:g}")
