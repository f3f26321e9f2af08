"""Hardware interfaces: what the controllers read and command, in joint space.

:class:`HardwareInterface` is the seam; :class:`hil.hardware.can_interface.CanHardwareInterface`
the CAN master behind it, :class:`FakeHardwareInterface` echoes the commands as
measurements, with no CAN and no physics.
"""

from __future__ import annotations

import math
import threading
from abc import ABC, abstractmethod
from collections.abc import Callable

import numpy as np

from hil.description import RobotDescription
from hil.hardware.axis import AxisFault
from hil.hardware.feedback import JointFeedback
from hil.hardware.sensor_states import ImuDescription, ImuState, WrenchState
from hil.realtime import Ring
from hil.realtime.stalls import Stall


class HardwareInterface(ABC):
    """Joint-space access to a robot's actuated joints (``joint_names`` order).

    What a control loop may read of it beyond the joints is declared here with the default
    of hardware that has none of it (``round_trips``, ``last_round_trip``,
    ``silence_cycles``, ``answer_deadlines``, ``imus`` and ``read_sensors``), as
    python-can's BusABC declares a bus' optional capabilities."""

    #: each cycle's round trip (s), from its commands out to the last answer in, where the
    #: hardware measures them (None: it does not)
    round_trips: Ring | None = None
    #: cycles without an answer after which the hardware calls a drive silent (0: it never
    #: does)
    silence_cycles: int = 0
    #: the round trip of the cycle :meth:`read` last took (s; NaN: not measured, or not every
    #: answer came)
    last_round_trip: float = math.nan
    #: the IMUs :meth:`read_sensors` gives samples of
    imus: tuple[ImuDescription, ...] = ()
    #: the force-torque sensors it gives samples of: (name, the link it is on) each
    force_torques: tuple[tuple[str, str], ...] = ()

    def __init__(self, robot: RobotDescription):
        self.robot = robot
        self.joint_names = tuple(j.name for j in robot.driven_joints)
        self.actuator_names = tuple(a.name for a in robot.actuators)

    @abstractmethod
    def start(self, cancel: threading.Event | None = None) -> JointFeedback:
        """Bring the hardware up until it follows position commands; return where it is.
        Setting ``cancel`` (from another thread) ends a bring-up that waits (HilError)."""

    @abstractmethod
    def read(self) -> JointFeedback:
        """The joint state the hardware reported for the last :meth:`write` (the start of a
        control cycle, as ros2_control's read)."""

    @abstractmethod
    def write(self, positions: np.ndarray, velocities: np.ndarray) -> None:
        """Send this cycle's commands (the end of a control cycle)."""

    def cycle(self, positions: np.ndarray, velocities: np.ndarray) -> JointFeedback:
        """:meth:`write`, then :meth:`read` what it brought (for scripts and tests)."""
        self.write(positions, velocities)
        return self.read()

    def faults(self) -> list[AxisFault]:
        """Faults found since the last call."""
        return []

    def reset_faults(self) -> None:
        """Clear latched faults and bring every actuator back to following commands; until
        :attr:`ready`, each holds where it is."""

    @property
    def ready(self) -> bool:
        """Whether every actuator follows commands (after start, or after a reset)."""
        return True

    def stop(self) -> None:
        """Leave every actuator disabled (brakes on where fitted)."""

    def answer_deadlines(self) -> dict[tuple[str, int], float]:
        """How long each drive (bus, node id) may go unanswered before it stops itself (its
        watchdog, s): what tells a silence the bench caused from one the drive reacted to.
        Empty where the hardware has no such drives."""
        return {}

    def watch_transport(self, on_stall: Callable[[Stall], None]) -> None:
        """From now on call ``on_stall`` (from any thread) with each late delivery the
        transport to the actuators reports; a transport that reports none ignores it."""

    def read_sensors(self) -> list[ImuState | WrenchState]:
        """The sensors' samples that arrived since the last call, without waiting (none
        where the hardware has no sensor)."""
        return []


class FakeHardwareInterface(HardwareInterface):
    """No CAN, no physics: the commanded state is the measured state."""

    def __init__(self, robot: RobotDescription):
        super().__init__(robot)
        n = len(self.joint_names)
        self._torques = np.zeros(len(self.actuator_names))
        self._states = ("FAKE",) * len(self.actuator_names)
        self._state = JointFeedback(np.zeros(n), np.zeros(n), np.zeros(n), self._torques,
                                    self._states)

    def start(self, cancel: threading.Event | None = None) -> JointFeedback:
        return self._state

    def read(self) -> JointFeedback:
        return self._state

    def write(self, positions, velocities) -> None:
        self._state = JointFeedback(np.array(positions, dtype=float),
                                    np.array(velocities, dtype=float), np.zeros(len(positions)),
                                    self._torques, self._states)
