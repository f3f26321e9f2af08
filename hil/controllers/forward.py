"""ros2_controllers' forward command controllers (forward_command_controller package):
``position_controllers/JointGroupPositionController`` and
``velocity_controllers/JointGroupVelocityController``, each the latest command array
(std_msgs/Float64MultiArray ``data``, one value per joint in ``joints`` order) written to
one command interface of its joints.

Stricter than ros2_controllers, by hil's choice (docs/controllers.md): a command of the wrong
size is refused with why (the JTC's sibling logs it and returns an error from update), and so
is a value that is not finite or lies outside the joint's position or velocity limit (the
original writes it to the hardware): a bad stream never moves a joint."""

from __future__ import annotations

import threading
from collections.abc import Sequence

import numpy as np

from hil.controllers.planning import JointLimitTable

#: the controller types hil runs, by the interface they command
FORWARD_TYPES = {"position_controllers/JointGroupPositionController": "position",
                 "velocity_controllers/JointGroupVelocityController": "velocity",
                 "forward_command_controller/ForwardCommandController": None}


class ForwardCommandController:
    """Writes the latest accepted command to ``interface`` of its joints; none until the
    first command after activation (the interfaces keep their last values, as in
    forward_command_controller's on_activate)."""

    def __init__(self, name: str, type_name: str, limits: JointLimitTable, interface: str):
        self.name, self.type_name, self.interface = name, type_name, interface
        self.joint_names = limits.names
        self.limits = limits
        self._lock = threading.Lock()
        self._command: np.ndarray | None = None

    @property
    def command_interfaces(self) -> tuple[str, ...]:
        return (self.interface,)

    #: none: its state_interface_configuration is NONE (forward_controllers_base.cpp)
    state_interfaces: tuple[str, ...] = ()

    def command(self, values: Sequence[float]) -> None:
        """Take a command array; ValueError, naming the joint, for one it refuses."""
        data = np.asarray(values, dtype=float)
        if data.shape != (len(self.joint_names),):
            raise ValueError(f"{self.name}: command size ({data.size}) does not match number "
                             f"of interfaces ({len(self.joint_names)}: "
                             f"{', '.join(self.joint_names)})")
        if self.interface == "position":
            lower, upper = self.limits.lower, self.limits.upper
            outside = ~self.limits.continuous & ((data < lower) | (data > upper))
        else:
            lower, upper = -self.limits.velocity, self.limits.velocity
            outside = (data < lower) | (data > upper)
        bad = ~np.isfinite(data) | outside
        if bad.any():
            k = int(np.argmax(bad))
            raise ValueError(f"{self.name}: joint '{self.joint_names[k]}' {self.interface} "
                             f"{data[k]:g} is outside [{lower[k]:g}, {upper[k]:g}]")
        with self._lock:
            self._command = data

    def activate(self, now: float, positions: np.ndarray) -> None:
        with self._lock:
            self._command = None

    def deactivate(self) -> None:
        with self._lock:
            self._command = None

    def update(self, now: float, positions: np.ndarray, velocities: np.ndarray
               ) -> tuple[np.ndarray | None, np.ndarray | None]:
        """(positions, velocities) to write, None where this controller writes nothing."""
        with self._lock:
            command = self._command
        if command is None:
            return None, None
        return (command, None) if self.interface == "position" else (None, command)
