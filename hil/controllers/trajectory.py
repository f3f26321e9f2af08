"""Joint trajectory controller, with ros2_controllers' joint_trajectory_controller semantics
(jazzy branch; each behaviour cites its source in tests/test_jtc_semantics.py).

* A goal is validated before any motion as the JTC's validate_trajectory_msg does (partial
  goals only with ``allow_partial_joints_goal``, a last point at rest unless
  ``allow_nonzero_velocity_at_trajectory_end``, no effort fields, a stamped goal that ends in
  the past) and against the robot's limits (hil's own: unknown, duplicate or mimic joints,
  ragged or non-finite points, positions outside the limits, velocities above them): each
  rejection names the joint and point.
* Interpolation follows what the points give: positions only -> linear, + velocities ->
  cubic, + accelerations -> quintic. The goal's clock starts at its header stamp (0: now);
  the first segment runs from the measured state now (the desired one with
  ``interpolate_from_desired_state``) to point 0. With
  ``allow_integration_in_goal_trajectories`` a point may leave out positions (and
  velocities): integrated from the point before (:mod:`hil.controllers.integration`).
* Path tolerances are checked while the trajectory runs, goal tolerances from its last point
  on: within ``goal_time`` (0: without a time limit) the goal succeeds, after it it aborts; a
  violation holds the measured position (or ramps down with ``decelerate_on_cancel``), as a
  cancel does. A new goal preempts the active one.
* Continuous joints: goal positions are unwrapped to the nearest turn and errors are the
  shortest angle.

This module holds the controller's state under its lock and its lifecycle; its jobs each
have a module: a goal checked and splined (:mod:`~hil.controllers.planning`), started from
the state now (:mod:`~hil.controllers.active_goal`), judged each cycle against its
tolerances (:mod:`~hil.controllers.tolerance_check`), the stop after a cancel or an abort
(:mod:`~hil.controllers.stopping`), and the state reported
(:mod:`~hil.controllers.controller_state`).
"""

from __future__ import annotations

import logging
import threading

import numpy as np

from hil.controllers.active_goal import ActiveGoal, start_goal
from hil.controllers.controller_state import ControllerState
from hil.controllers.goal import (
    DEACTIVATED, HARDWARE_FAULT, INVALID_GOAL, PREEMPTED, SUCCESSFUL, GoalRejected,
    GoalResult, GoalStatus, TrajectoryGoal,
)
from hil.controllers.parameters import JtcParameters
from hil.controllers.planning import JointLimitTable, plan_goal
from hil.controllers.stop_ramp import StopRamp
from hil.controllers.stopping import stop_ramp
from hil.controllers.tolerance_check import judge
from hil.description import RobotDescription

log = logging.getLogger(__name__)


class JointTrajectoryController:
    """Position-commanding trajectory controller over ``parameters.joints`` (the robot's
    driven joints by default), with the JTC's parameters.

    Thread-safe: goals and cancels may arrive from any thread; :meth:`update` runs in the
    control loop. Inactive (see :meth:`activate`) it refuses goals, as the JTC does."""

    type_name = "joint_trajectory_controller/JointTrajectoryController"

    def __init__(self, robot: RobotDescription, parameters: JtcParameters | None = None,
                 name: str = "joint_trajectory_controller"):
        self.name = name
        driven = {j.name: j for j in robot.driven_joints}
        if parameters is None:
            parameters = JtcParameters(joints=tuple(driven))
        unknown = [name for name in parameters.joints if name not in driven]
        if unknown:
            raise ValueError(f"joint(s) {', '.join(unknown)} are not driven joints of "
                             f"{robot.name}: {', '.join(driven)}")
        self.joints = tuple(driven[name] for name in parameters.joints)
        self.joint_names = parameters.joints
        self.parameters = parameters
        self.limits = JointLimitTable.of(robot, self.joints)
        n = len(self.joints)
        self._lock = threading.Lock()
        self._active: ActiveGoal | None = None
        self._ramp: StopRamp | None = None
        self._finished: list[tuple[str, GoalResult]] = []
        self._desired = np.zeros(n)
        self._desired_velocity = np.zeros(n)
        self._desired_acceleration = np.zeros(n)
        self._initialised = False
        self._running = True
        self._actual = np.zeros(n)
        self._actual_velocity = np.zeros(n)
        self._now = 0.0
        self._fault: str | None = None

    @property
    def command_interfaces(self) -> tuple[str, ...]:
        return self.parameters.command_interfaces

    @property
    def state_interfaces(self) -> tuple[str, ...]:
        """Each joint's state interfaces it requires (state_interface_configuration)."""
        return self.parameters.state_interfaces

    def set_parameters(self, changes: dict[str, float | bool]) -> None:
        """Change settable parameters (:meth:`JtcParameters.settable`, ROS names) for the
        goals accepted from now on (the active goal keeps its tolerances, as in the JTC);
        ValueError, changing nothing, for an unknown name or a bad value. Any thread."""
        changed = self.parameters.changed(changes)
        with self._lock:
            self.parameters = changed

    # --- lifecycle (controller_manager's activate/deactivate) ---------------------------

    def activate(self, now: float, positions: np.ndarray) -> None:
        """Run again from ``now`` (the controller clock), holding ``positions`` (the last
        commands: the JTC's set_last_command_interface_value_as_state_on_activation)."""
        with self._lock:
            self._running = True
            self._now = now
            self._ramp = None
            self._desired = np.array(positions, dtype=float)
            self._desired_velocity = np.zeros_like(self._desired)
            self._desired_acceleration = np.zeros_like(self._desired)
            # measured again at the next cycle; a goal before it starts from the commands
            self._actual, self._actual_velocity = self._desired.copy(), np.zeros_like(
                self._desired)
            self._initialised = True

    def deactivate(self) -> None:
        """Stop taking goals; the active one is aborted as the JTC's on_deactivate does."""
        with self._lock:
            self._running = False
            if self._active is not None and self._active.result is None:
                self._finish(self._active, GoalResult(GoalStatus.ABORTED, INVALID_GOAL,
                                                      DEACTIVATED))

    # --- goals ------------------------------------------------------------------

    def submit(self, goal_id: str, goal: TrajectoryGoal) -> None:
        """Validate and start a goal, preempting the active one; raises GoalRejected.

        The goal is checked and planned without the controller's lock (a 10,000-point goal
        takes milliseconds): the control cycle waits only for the first segment, planned
        from its state under the lock. Points integrated from the state are planned from
        the state when the goal arrives, and again under the lock only if it has changed
        (hil's choice: the goal is judged on that state)."""
        with self._lock:
            self._check_accepting()
            parameters, now, before = self.parameters, self._now, self._state_before()
        plan = plan_goal(self.limits, parameters, goal)
        if plan.integrating is not None:
            stamp = now if goal.start_time is None else goal.start_time
            plan.spline_from(self.limits, goal.joint_names,
                             *(values[plan.indices] for values in before), at=now - stamp)
        if plan.tolerance_warning:
            log.warning("goal %s: %s", goal_id, plan.tolerance_warning)
        with self._lock:
            self._check_accepting()
            active = start_goal(goal_id, goal, plan, self.limits, self.parameters, self._now,
                                self._state_before(plan.indices))
            if self._active is not None and self._active.result is None:
                self._finish(self._active, GoalResult(GoalStatus.ABORTED, INVALID_GOAL,
                                                      PREEMPTED))
            self._active, self._ramp = active, None

    def _check_accepting(self) -> None:
        if not self._running:
            raise GoalRejected("Can't accept new action goals. Controller is not running.")
        if self._fault is not None:
            raise GoalRejected(f"the hardware is faulted: {self._fault}", HARDWARE_FAULT)
        if not self._initialised:
            raise GoalRejected("the controller has no joint state yet (hardware starting)",
                               HARDWARE_FAULT)

    def cancel(self, goal_id: str) -> bool:
        """Cancel a goal: the joints hold where they are (or ramp down). False if it is not
        active."""
        with self._lock:
            if self._active is None or self._active.goal_id != goal_id or self._active.result:
                return False
            self._stop_moving()
            self._finish(self._active, GoalResult(GoalStatus.CANCELED, SUCCESSFUL))
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
            elif self._ramp is not None:
                self._desired, self._desired_velocity, self._desired_acceleration = \
                    self._ramp.sample(now)
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

    def _follow(self, goal: ActiveGoal, now: float) -> None:
        """The JTC's update for a goal: sample it, then judge its tolerances
        (:func:`hil.controllers.tolerance_check.judge`)."""
        idx, t = goal.indices, now - goal.start
        p, v, a = goal.spline.sample(t)
        self._desired[idx], self._desired_velocity[idx], self._desired_acceleration[idx] = p, v, a
        late = t - goal.spline.end
        if late >= 0.0:
            self._desired_velocity[idx] = self._desired_acceleration[idx] = 0.0
        first, goal.sampled = not goal.sampled, True
        velocity_error = (self._desired_velocity - self._actual_velocity
                          if self.parameters.commands_velocity
                          else np.zeros_like(self._desired))
        ending = judge(goal, late, first, self._desired - self._actual, velocity_error,
                       self.limits.continuous, self.parameters, self.joint_names)
        if ending is not None:
            if ending.stop:
                self._stop_moving()
            self._finish(goal, ending.result)

    def _finish(self, goal: ActiveGoal, result: GoalResult) -> None:
        goal.result = result
        self._finished.append((goal.goal_id, result))

    def _stop_moving(self) -> None:
        """After a cancel or an abort: hold the measured position, or ramp down to rest
        (:func:`hil.controllers.stopping.stop_ramp`)."""
        self._ramp = stop_ramp(self.parameters, self.joint_names, self._now, self._actual,
                               self._actual_velocity)
        if self._ramp is None:
            self._hold_actual()
        else:
            self._desired, self._desired_velocity, self._desired_acceleration = \
                self._ramp.sample(self._now)

    def _hold_actual(self) -> None:
        self._ramp = None
        self._desired = self._actual.copy()
        self._desired_velocity = np.zeros_like(self._desired)
        self._desired_acceleration = np.zeros_like(self._desired)

    def _state_before(self, indices: np.ndarray | slice = slice(None)
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The JTC's point before the trajectory (set_point_before_trajectory_msg): the last
        command with interpolate_from_desired_state, else the measured state, whose velocity
        is 0 without a velocity state interface (read_state_from_state_interfaces leaves it
        empty, and the trajectory fills it with 0) and whose acceleration is 0 (hil's
        hardware has no acceleration state interface)."""
        if self.parameters.interpolate_from_desired_state:
            return (self._desired[indices].copy(), self._desired_velocity[indices].copy(),
                    self._desired_acceleration[indices].copy())
        here = self._actual[indices].copy()
        measured = "velocity" in self.parameters.state_interfaces
        v0 = self._actual_velocity[indices].copy() if measured else np.zeros_like(here)
        return here, v0, np.zeros_like(here)

