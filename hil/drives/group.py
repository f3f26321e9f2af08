"""The drive cores of one plant, stepped together: compiled with the core (setup.py), so a
plant step's loop over its drives calls each core's compiled methods directly, not through
the interpreter (two loops of six calls at each of a ur3's two steps a cycle)."""

from __future__ import annotations

from hil.drives.core import DriveCore


class CoreGroup:
    """Drive cores, each driving one plant actuator (its index in the plant's order)."""

    def __init__(self, actuators: int):
        self._cores: list[DriveCore] = []
        self._actuators: list[int] = []
        # the torque of each plant actuator, as the last update left it (0 where no core)
        self._torques: list[float] = [0.0] * actuators

    def add(self, core: DriveCore, actuator: int) -> None:
        self._cores.append(core)
        self._actuators.append(actuator)

    def update(self, dt: float) -> list[float]:
        """Each core's inner loops advanced by ``dt``: the torques of the plant's actuators,
        in the plant's order (0 where no core drives one; the same list each call)."""
        torques = self._torques
        actuators = self._actuators
        for k, core in enumerate(self._cores):
            torques[actuators[k]] = core.update(dt)
        return torques

    def any_events(self) -> bool:
        """Whether a core has faults its drive has not taken (its ``events``)."""
        for core in self._cores:
            if core.events:
                return True
        return False

    def measure(self, positions: list[float], velocities: list[float], dt: float) -> None:
        """Each core's motor position and velocity from the plant's (its actuator's), ``dt``
        after the last (0: the first)."""
        actuators = self._actuators
        for k, core in enumerate(self._cores):
            actuator = actuators[k]
            core.measure(positions[actuator], velocities[actuator], dt)
