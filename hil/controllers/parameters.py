"""The joint trajectory controller's parameters, named and defaulted as ros2_controllers'
joint_trajectory_controller declares them (jazzy branch,
joint_trajectory_controller/src/joint_trajectory_controller_parameters.yaml), and the
tolerances a goal runs with (include/joint_trajectory_controller/tolerances.hpp).

hil runs the JTC over the joints of its bus config; the parameters hil reads are the ones a
client can observe. ``hil.reject_unreachable_first_point`` is hil's own: where it stays
stricter than the JTC (docs/controllers.md)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

#: the command interfaces hil's hardware interface exports per joint: drives in
#: cyclic synchronous position take a position with a velocity feed-forward
COMMAND_INTERFACES = ("position", "velocity")

#: control_msgs/JointTolerance: -1 erases a tolerance (tolerances.hpp, resolve_tolerance_source
#: compares within float epsilon)
ERASE = -1.0
FLOAT_EPSILON = float(np.finfo(np.float32).eps)


@dataclass(frozen=True)
class JointConstraint:
    """``constraints.<joint>``: ``trajectory`` (path) and ``goal`` position tolerances
    (0: not checked) and ``max_deceleration_on_cancel`` (decelerate_on_cancel)."""

    trajectory: float = 0.0
    goal: float = 0.0
    max_deceleration_on_cancel: float = 0.0


@dataclass(frozen=True)
class JtcParameters:
    """The JTC's parameters hil honours, with the JTC's defaults."""

    joints: tuple[str, ...]
    command_interfaces: tuple[str, ...] = ("position",)
    state_interfaces: tuple[str, ...] = ("position", "velocity")
    allow_partial_joints_goal: bool = False
    allow_nonzero_velocity_at_trajectory_end: bool = False
    interpolate_from_desired_state: bool = False
    #: a point may leave out positions (and velocities): integrated from the point before
    #: (hil.controllers.integration)
    allow_integration_in_goal_trajectories: bool = False
    action_monitor_rate: float = 20.0
    cmd_timeout: float = 0.0
    stopped_velocity_tolerance: float = 0.01
    goal_time: float = 0.0
    decelerate_on_cancel: bool = False
    constraints: dict[str, JointConstraint] = field(default_factory=dict)
    #: hil's own: refuse a goal whose first point the joints cannot reach in its time at
    #: their velocity limits (the JTC jumps there); False for the JTC's behaviour
    reject_unreachable_first_point: bool = True

    def constraint(self, joint: str) -> JointConstraint:
        return self.constraints.get(joint, JointConstraint())

    @property
    def commands_velocity(self) -> bool:
        """Whether velocity is commanded and measured: the JTC then computes velocity errors
        (compute_error_for_joint), so velocity tolerances can fail."""
        return "velocity" in self.command_interfaces and "velocity" in self.state_interfaces

    def defaults(self) -> SegmentTolerances:
        """The tolerances of a goal that sets none (get_segment_tolerances(params))."""
        n = len(self.joints)
        return SegmentTolerances(
            path_position=np.array([self.constraint(j).trajectory for j in self.joints]),
            path_velocity=np.zeros(n),
            goal_position=np.array([self.constraint(j).goal for j in self.joints]),
            goal_velocity=np.full(n, self.stopped_velocity_tolerance),
            goal_time=self.goal_time)

    def effective_cmd_timeout(self) -> float:
        """cmd_timeout where it applies: it must exceed constraints.goal_time, else the JTC
        ignores it (on_activate)."""
        return self.cmd_timeout if self.cmd_timeout > self.goal_time else 0.0

    # --- settable at run time, as the JTC's parameter listener takes them -------------------

    def settable(self) -> dict[str, float | bool]:
        """The parameters a client may change while the controller runs, by their ROS
        names, with their values (read-only ones: joints, interfaces, decelerate_on_cancel,
        max_deceleration_on_cancel, action_monitor_rate)."""
        values: dict[str, float | bool] = {
            "allow_partial_joints_goal": self.allow_partial_joints_goal,
            "allow_nonzero_velocity_at_trajectory_end":
                self.allow_nonzero_velocity_at_trajectory_end,
            "interpolate_from_desired_state": self.interpolate_from_desired_state,
            "allow_integration_in_goal_trajectories":
                self.allow_integration_in_goal_trajectories,
            "reject_unreachable_first_point": self.reject_unreachable_first_point,
            "cmd_timeout": self.cmd_timeout,
            "constraints.stopped_velocity_tolerance": self.stopped_velocity_tolerance,
            "constraints.goal_time": self.goal_time}
        for joint in self.joints:
            values[f"constraints.{joint}.trajectory"] = self.constraint(joint).trajectory
            values[f"constraints.{joint}.goal"] = self.constraint(joint).goal
        return values

    def changed(self, changes: dict[str, float | bool]) -> JtcParameters:
        """These parameters with ``changes`` (ROS names of :meth:`settable`); ValueError,
        naming the parameter, for an unknown or read-only name or a value of the wrong kind
        (a number must be finite and >= 0, as the JTC's validation ``gt_eq<>: 0.0``)."""
        known = self.settable()
        updated, constraints = {}, dict(self.constraints)
        for name, value in changes.items():
            if name not in known:
                raise ValueError(f"no settable parameter '{name}'; there are: "
                                 f"{', '.join(known)}")
            if isinstance(known[name], bool):
                if not isinstance(value, bool):
                    raise ValueError(f"{name} is a bool, not {value!r}")
            elif isinstance(value, bool) or not isinstance(value, (int, float)) or \
                    not math.isfinite(value) or value < 0:
                raise ValueError(f"{name} must be a finite number >= 0, not {value!r}")
            if name.startswith("constraints.") and name.endswith((".trajectory", ".goal")) \
                    and name.count(".") >= 2:
                joint, what = name.removeprefix("constraints.").rsplit(".", 1)
                # onto this change's constraint, not the original: a joint's trajectory and
                # goal set together both take effect (each parameter is its own assignment
                # in the JTC's generated parameter listener)
                constraints[joint] = replace(constraints.get(joint, JointConstraint()),
                                             **{what: float(value)})
            else:
                updated[name.removeprefix("constraints.")] = value
        return replace(self, constraints=constraints, **updated)


@dataclass(frozen=True)
class SegmentTolerances:
    """The tolerances a goal runs with, per controller joint (0: not checked)."""

    path_position: np.ndarray
    path_velocity: np.ndarray
    goal_position: np.ndarray
    goal_velocity: np.ndarray
    goal_time: float          # 0: wait for the goal tolerance without a time limit


def resolve(default: float, given: float) -> float:
    """A goal's tolerance over the default (resolve_tolerance_source): > 0 replaces it, -1
    erases it (0: not checked), 0 keeps the default; ValueError for another negative.
    (A NaN, which no C++ client sends, compares as the JTC compares it: the default.)"""
    if given > 0.0:
        return given
    if abs(given - ERASE) < FLOAT_EPSILON:
        return 0.0
    if given < 0.0:
        raise ValueError("Illegal tolerance value.")
    return default
