"""The compared cycles' measured values, logged and replayed, summed up into the report's
joint statistics a batch at a time (numpy's work), and kept for ``--record``."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from hil.drives.profile import Reading
from hil.replay.compare import JointStatistics
from hil.replay.report import Report

#: the statistics' quantities by name
QUANTITY_INDEX = {q: i for i, q in enumerate(JointStatistics.QUANTITIES)}
#: cycles summed up at a time (the statistics are numpy's work, a batch at a time)
BATCH = 512


class CycleRows:
    """Per cycle, a flat list: (logged, replayed) x quantity x actuator, motor side SI (NaN:
    none yet), filled as frames come."""

    def __init__(self, report: Report, actuators: int, keep_values: bool):
        self._report = report
        self._width = actuators
        self._keep_values = keep_values
        #: cycle -> its row, until summed up
        self.rows: dict[int, list[float]] = {}

    def add(self, actuator: int, cycle: int, expected: Sequence[Reading],
            got: Sequence[Reading]) -> None:
        """A cycle's first reading of each quantity of a drive, logged and replayed."""
        width = self._width
        row = self.rows.get(cycle)
        if row is None:
            row = self.rows[cycle] = [math.nan] * (6 * width)
        for side, readings in ((0, expected), (1, got)):
            for reading in readings:
                q = QUANTITY_INDEX.get(reading.quantity)
                if q is not None:
                    k = (3 * side + q) * width + actuator
                    if row[k] != row[k]:                     # NaN: none yet this cycle
                        row[k] = reading.value * reading.scale

    def flush(self, before: int | None) -> None:
        """Sum up the cycles before ``before`` (all: None), once BATCH of them are done."""
        done = sorted(c for c in self.rows if before is None or c < before)
        if not done or (before is not None and len(done) < BATCH):
            return
        rows = np.array([self.rows.pop(c) for c in done]).reshape(len(done), 2, 3,
                                                                   self._width)
        cycles = np.array(done)
        statistics = self._report.statistics
        statistics.add(cycles, rows[:, 1] - rows[:, 0])
        if self._keep_values:
            position, torque = (JointStatistics.QUANTITIES.index(q) for q in ("position", "torque"))
            self._report.values.append((cycles, *(
                statistics.joint_values(q, rows[:, side, q].T, absolute=True)
                for q in (position, torque) for side in (0, 1))))
