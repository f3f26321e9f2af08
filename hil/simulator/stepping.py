"""The plant stepped in time with its drives' inner loops: one step at a time, and in real
time up to the present of a clock."""

from __future__ import annotations

import time
from collections.abc import Callable

from hil.drives import DriveProfile
from hil.drives.group import CoreGroup
from hil.plant import Plant
from hil.sensors.imu import SimulatedImu

#: real time: a gap longer than this (a stalled process) is skipped, not replayed (s)
MAX_CATCH_UP = 0.05


class PlantStepping:
    """The plant and the drives whose inner loops run at each of its steps (the simulator's
    lock held at every call)."""

    def __init__(self, plant: Plant):
        self.plant = plant
        #: every drive, in the config's order (added by :func:`simulated_buses`)
        self.drives: list[DriveProfile] = []
        # whose after_update runs after every step, and whose only after a step that left
        # its core events (DriveProfile.follows_every_step)
        self._every_step: list[DriveProfile] = []
        self._on_events: list[DriveProfile] = []
        #: each drive's core with its plant actuator index, walked at every plant step
        self._cores = CoreGroup(len(plant.actuator_names))
        #: the sensors sampling the plant after each step (hil.sensors)
        self.sensors: list[SimulatedImu] = []

    def add(self, drive: DriveProfile, actuator: int) -> None:
        """A drive whose core drives the plant's actuator of index ``actuator``."""
        self.drives.append(drive)
        self._cores.add(drive.core, actuator)
        (self._every_step if drive.follows_every_step else self._on_events).append(drive)

    def step(self) -> None:
        """One plant step with the drives' inner loops."""
        dt = self.plant.timestep
        self.plant.set_motor_torques(self._cores.update(dt))
        self.plant.step()
        self.measure(dt)
        for drive in self._every_step:
            drive.after_update()
        if self._on_events and self._cores.any_events():     # a fault, rarely
            for drive in self._on_events:
                if drive.core.events:
                    drive.after_update()
        for sensor in self.sensors:
            sensor.after_step(self.plant.time)

    def measure(self, dt: float = 0.0) -> None:
        """Each drive's motor position and velocity now, ``dt`` after the last (0: the
        first)."""
        # Python floats: numpy scalars make every drive's loop arithmetic slower
        # (docs/performance.md, "2026-12-06, later: figures from code comments")
        self._cores.measure(self.plant.motor_positions().tolist(),
                            self.plant.motor_velocities().tolist(), dt)


class RealTimeClock:
    """Real time: plant time following a clock (the wall clock unless told another), the plant
    stepped up to its present whenever :meth:`advance` is called (by the simulator's lock,
    :class:`hil.realtime.present.PlantPresent`, on entry)."""

    def __init__(self, stepping: PlantStepping):
        self._plant = stepping.plant
        self._step = stepping.step
        self.wall_clock: Callable[[], float] = time.perf_counter
        #: while the plant follows the clock: (its epoch, plant steps done since)
        self.started: tuple[float, int] | None = None
        #: no step past this one (a run of a given duration)
        self.last_step: int | None = None
        self.overruns = 0          # gaps skipped (the process stalled)

    def start(self) -> None:
        """From now on plant time follows the clock, from its present reading."""
        self.started = (self.wall_clock(), 0)

    def advance(self) -> None:
        """Step the plant up to the clock. A gap over MAX_CATCH_UP is skipped and counted in
        :attr:`overruns`: the plant then lags the clock."""
        if self.started is None:
            return
        epoch, done = self.started
        dt = self._plant.timestep
        due = int((self.wall_clock() - epoch) / dt) - done
        if due > MAX_CATCH_UP / dt:
            self.overruns += 1
            epoch += (due - 1) * dt
            due = 1
        if self.last_step is not None:
            due = min(due, self.last_step - round(self._plant.time / dt))
        for _ in range(due):
            self._step()
        self.started = (epoch, done + max(due, 0))
