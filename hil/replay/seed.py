"""On the log's clock, the replay's plant placed where the log's drives first reported their
joints once the master cycles (that run's plant, or the robot, moved before the log began),
and the first cycle whose measured values are compared: SETTLE cycles later (the drives'
controllers settle on the log's state). A lock-step run's log began with its plant: nothing
to place, every cycle compared.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np

from hil.drives.profile import Reading
from hil.replay.compare import JointStatistics
from hil.simulator import Simulator

#: the quantities a replay's plant is placed by (position, velocity of each actuator)
SEEDED = {"position": 0, "velocity": 1}
#: cycles after the plant is placed before measured values are compared
SETTLE = 10
#: how long (s of the log) a replay waits for every drive's first position
SEED_WAIT = 1.0


class PlantSeed:
    """The log's first position and velocity of each actuator (motor side, SI), until the
    plant is placed by them."""

    def __init__(self, clock: str, actuators: int):
        self._first = np.full((2, actuators), math.nan)
        self._first_report: float | None = None
        #: the first cycle whose measured values are compared: a lock-step run's log began
        #: with its plant (nothing to place), else once the plant is placed
        self.measured_from: float = 0 if clock == "cycles" else math.inf

    @property
    def placed(self) -> bool:
        """Whether the plant is where the log's was (placed, or a lock-step log's)."""
        return self.measured_from < math.inf

    def note(self, actuator: int, readings: Iterable[Reading]) -> None:
        """A logged drive's readings before the plant is placed: the first position and
        velocity of its actuator kept."""
        for reading in readings:
            q = SEEDED.get(reading.quantity)
            if q is not None and math.isnan(self._first[q, actuator]):
                self._first[q, actuator] = reading.value * reading.scale

    def ready(self, now: float) -> bool:
        """Every drive reported its position (a master starts its drives one by one), or
        SEED_WAIT passed since the first did (a drive that never reports one)."""
        reported = ~np.isnan(self._first[0])
        if not reported.any():
            return False
        if self._first_report is None:
            self._first_report = now
        return bool(reported.all()) or now - self._first_report > SEED_WAIT

    def place(self, sim: Simulator, statistics: JointStatistics, cycle_hz: float) -> int:
        """The plant placed where the log's drives first reported their joints, moving as
        they reported (a real-time run's plant, or a robot, was running before the log
        began: joints fell or were moved); the joints placed. Measured values are compared
        SETTLE cycles later."""
        positions = statistics.joint_values(0, self._first[0][:, None], absolute=True)[:, 0]
        velocities = statistics.joint_values(1, self._first[1][:, None], absolute=False)[:, 0]
        with sim.lock:
            sim.plant.set_joint_positions(
                {j: p for j, p in zip(statistics.joints, positions) if not math.isnan(p)},
                {j: v for j, v in zip(statistics.joints, velocities) if not math.isnan(v)})
        # the drives' answers to this cycle carry what they sampled before, and their
        # controllers' own state (integrals, filters) takes a few cycles to be the log's
        self.measured_from = round(sim.plant.time * cycle_hz) + SETTLE
        return int(np.sum(~np.isnan(positions)))
