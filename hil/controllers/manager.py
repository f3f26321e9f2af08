"""Controllers over one hardware interface, listed and switched as ros2_control's
controller_manager does it (controller_manager.cpp, jazzy: switch_controller_cb,
check_for_interfaces_availability_to_activate; controller_manager_msgs/SwitchController).

Each controller claims command interfaces (``joint/position``, ``joint/velocity``); two
active controllers never claim the same one. A switch deactivates, then activates, between
two control cycles; an activated controller starts from the last commands. Each cycle the
active controllers' outputs make the hardware's commands:

* a joint whose position interface is claimed gets that position (and the claimed velocity,
  else 0, as the velocity feed-forward);
* a joint whose velocity interface alone is claimed gets its last position command advanced
  by the velocity over the period, within its limits: hil's drives run cyclic synchronous
  position, and this is how they follow a velocity (hil's choice);
* a joint nobody commands holds its last position command.
"""

from __future__ import annotations

import threading
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from hil.controllers.config import ControllersConfig
from hil.controllers.forward import ForwardCommandController
from hil.controllers.planning import JointLimitTable
from hil.controllers.switch import Strictness, SwitchResult, plan_switch
from hil.controllers.trajectory import JointTrajectoryController
from hil.description import RobotDescription


class Controller(Protocol):
    """What the manager needs of a controller (JointTrajectoryController,
    ForwardCommandController)."""

    name: str
    type_name: str
    joint_names: tuple[str, ...]

    @property
    def command_interfaces(self) -> tuple[str, ...]: ...

    @property
    def state_interfaces(self) -> tuple[str, ...]: ...

    def activate(self, now: float, positions: np.ndarray) -> None: ...

    def deactivate(self) -> None: ...

    def update(self, now: float, positions: np.ndarray, velocities: np.ndarray
               ) -> tuple[np.ndarray | None, np.ndarray | None]: ...


@dataclass(frozen=True)
class ControllerInfo:
    """A controller as controller_manager_msgs/ControllerState lists it."""

    name: str
    state: str                   # "active" or "inactive"
    type: str
    claimed_interfaces: tuple[str, ...]
    required_command_interfaces: tuple[str, ...]
    required_state_interfaces: tuple[str, ...]


class ControllerManager:
    """Runs the active controllers each cycle over ``limits.names`` (the hardware's joints,
    in its order). Thread-safe: list and switch from any thread, :meth:`update` in the loop."""

    def __init__(self, limits: JointLimitTable, controllers: Sequence[Controller],
                 active: Sequence[str], period: float):
        self.limits, self.period = limits, period
        self.joint_names = limits.names
        self._controllers = {c.name: c for c in controllers}
        self._indices = {c.name: np.array([self.joint_names.index(j) for j in c.joint_names])
                         for c in controllers}
        self._active: list[str] = []
        self._lock = threading.Lock()
        self._position = np.zeros(len(self.joint_names))
        self._now = 0.0                 # the last cycle's time (activations start from it)
        self._started = False
        unknown = [name for name in active if name not in self._controllers]
        if unknown:
            raise ValueError(f"no controller named {', '.join(unknown)} to activate")
        for controller in controllers:      # loaded and configured: inactive until the start
            controller.deactivate()
        self._pending = list(active)

    @classmethod
    def from_config(cls, robot: RobotDescription, joint_names: tuple[str, ...],
                    config: ControllersConfig, period: float) -> ControllerManager:
        """The controllers of ``config`` over the hardware's ``joint_names``."""
        driven = {j.name: j for j in robot.driven_joints}
        limits = lambda names: JointLimitTable.of(  # noqa: E731
            robot, tuple(driven[n] for n in names))
        trajectory = JointTrajectoryController(robot, config.trajectory,
                                               config.trajectory_name)
        forwards = [ForwardCommandController(f.name, f.type, limits(f.joints), f.interface)
                    for f in config.forwards]
        return cls(limits(joint_names), [trajectory, *forwards], config.active, period)

    @property
    def trajectory(self) -> JointTrajectoryController:
        """The joint trajectory controller (hil runs one, active or not)."""
        return next(c for c in self._controllers.values()
                    if isinstance(c, JointTrajectoryController))

    def forward(self, name: str) -> ForwardCommandController:
        """The forward command controller ``name``; KeyError naming those there are."""
        controller = self._controllers.get(name)
        if not isinstance(controller, ForwardCommandController):
            raise KeyError(f"no forward command controller '{name}'; there are: "
                           f"{', '.join(self.forward_names())}")
        return controller

    def forward_names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self._controllers.values()
                     if isinstance(c, ForwardCommandController))

    def claims(self, name: str) -> tuple[str, ...]:
        """A controller's command interfaces as ``joint/interface``."""
        controller = self._controllers[name]
        return tuple(f"{joint}/{interface}" for joint in controller.joint_names
                     for interface in controller.command_interfaces)

    def list(self) -> list[ControllerInfo]:
        with self._lock:
            active = set(self._active)
        return [ControllerInfo(
            name, "active" if name in active else "inactive", c.type_name,
            self.claims(name) if name in active else (), self.claims(name),
            tuple(f"{joint}/{state}" for joint in c.joint_names
                  for state in c.state_interfaces))
            for name, c in self._controllers.items()]

    def is_active(self, name: str) -> bool:
        with self._lock:
            return name in self._active

    def switch(self, activate: Sequence[str], deactivate: Sequence[str],
               strictness: Strictness = Strictness.STRICT) -> SwitchResult:
        """Deactivate, then activate, as controller_manager's switch_controller decides it
        (:func:`hil.controllers.switch.plan_switch`), between two cycles: activate_asap or
        not, the next cycle runs the new controllers."""
        with self._lock:
            return self._switch(list(activate), list(deactivate), strictness)

    def _switch(self, activate: list[str], deactivate: list[str],
                strictness: Strictness) -> SwitchResult:
        plan = plan_switch(activate, deactivate, strictness,
                           {name: self.claims(name) for name in self._controllers},
                           self._active, self.joint_names)
        if isinstance(plan, SwitchResult):
            return plan
        for name in plan.deactivate:
            self._controllers[name].deactivate()
            self._active.remove(name)
        for name in plan.activate:
            self._controllers[name].activate(self._now,
                                             self._position[self._indices[name]].copy())
            self._active.append(name)
        return SwitchResult(True, plan.message)

    def update(self, now: float, positions: np.ndarray, velocities: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
        """One cycle: the active controllers' outputs, as the hardware's position and
        velocity commands (see the module's rules)."""
        with self._lock:
            self._now = now
            if not self._started:       # the first cycle: hold where the joints are
                self._position = np.array(positions, dtype=float)
                self._started = True
                self._switch(self._pending, [], Strictness.BEST_EFFORT)
            position = self._position.copy()
            # np.zeros, not zeros_like: the latter is a Python function around it (a cycle)
            velocity = np.zeros(len(position))
            claimed_positions, velocities_alone = [], []     # each controller's joints
            for name in self._active:
                controller, idx = self._controllers[name], self._indices[name]
                out_position, out_velocity = controller.update(now, positions[idx],
                                                               velocities[idx])
                interfaces = controller.command_interfaces
                claims_position = out_position is not None and "position" in interfaces
                if claims_position:
                    position[idx] = out_position
                    claimed_positions.append(idx)
                if out_velocity is not None and "velocity" in interfaces:
                    velocity[idx] = out_velocity
                    if not claims_position:
                        velocities_alone.append(idx)
            if velocities_alone:          # (the masks made only then: a cycle's numpy calls)
                self._integrate(position, velocity, velocities_alone, claimed_positions)
            self._position = position
            return position.copy(), velocity

    def _integrate(self, position: np.ndarray, velocity: np.ndarray,
                   velocities_alone: list[np.ndarray], claimed_positions: list[np.ndarray]
                   ) -> None:
        """The joints whose velocity alone is claimed (by any controller: another may claim
        a joint's position) advance their last position command by it, within limits."""
        integrate = np.zeros(len(position), dtype=bool)
        integrate[np.concatenate(velocities_alone)] = True
        for idx in claimed_positions:
            integrate[idx] = False
        # not .any(), a Python function in numpy and slower (docs/performance.md,
        # "2026-12-01: the in-process cycle in a fifth fewer instructions")
        if np.count_nonzero(integrate):
            position[integrate] = np.clip(
                self._position[integrate] + velocity[integrate] * self.period,
                self.limits.lower[integrate], self.limits.upper[integrate])

    def hold(self, positions: np.ndarray) -> None:
        """After a hardware fault: every joint holds ``positions`` and each active controller
        starts again from them (a streaming controller forgets its command: a stale velocity
        must not move a joint after the reset)."""
        with self._lock:
            self._position = np.array(positions, dtype=float)
            for name in self._active:
                self._controllers[name].activate(self._now,
                                             self._position[self._indices[name]].copy())
