"""What a replay found: the divergences (the first, and the first cycle's), the per-joint
statistics, and how fast it went."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from hil.replay.compare import Divergence, JointStatistics

#: divergences kept in the report beside the first (the count goes on)
KEPT = 20


@dataclass
class Report:
    """What a replay found."""

    clock: str
    cycles: int = 0                       # the replayed plant's control cycles
    wall_seconds: float = 0.0             # what the replay took
    compared: int = 0                     # answers compared one for one
    states_checked: int = 0               # timed states (heartbeats) found in order
    derived_unchecked: int = 0            # derived values not held to a tolerance
    after_the_log: int = 0                # replayed answers after the log's end
    sensor_frames: int = 0                # sensors' frames compared byte for byte
    sensor_frames_unchecked: int = 0      # a real-time log's sensors' frames, not compared
    divergences: list[Divergence] = field(default_factory=list)
    divergence_count: int = 0
    #: drive label -> its divergences
    by_drive: dict[str, int] = field(default_factory=dict)
    statistics: JointStatistics | None = None
    #: --record: batches of compared cycles (cycles, then the logged and the replayed joint
    #: positions and torques: 4 arrays of the statistics' joints x those cycles)
    values: list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = \
        field(default_factory=list)

    @property
    def first(self) -> Divergence | None:
        """The earliest divergence (by cycle), the largest of its cycle."""
        if not self.divergences:
            return None
        return min(self.divergences, key=lambda d: (d.cycle, -d.size))

    def first_cycle(self) -> list[Divergence]:
        """Every kept divergence of the first divergent cycle, largest first."""
        first = self.first
        if first is None:
            return []
        return sorted((d for d in self.divergences if d.cycle == first.cycle),
                      key=lambda d: -d.size)

    seeded: int = 0                       # joints placed where the log first had them
    before_seed: int = 0                  # measured values before that, not compared
    plant_seconds: float = 0.0            # the replayed plant's time
    survey_seconds: float = 0.0           # what reading the log first took

    @property
    def speed(self) -> float:
        """The plant's time replayed per second of wall time (the survey's included): how
        much faster than real time the log was replayed."""
        wall = self.wall_seconds + self.survey_seconds
        return self.plant_seconds / wall if wall > 0 else math.nan
