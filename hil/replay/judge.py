"""Each pair of a drive's answers, the log's and the replay's, compared: the same bytes, or
every value within its tolerance (measured values once the plant is where the log's was),
else a divergence in the report; the compared cycles' measured values to the statistics.

On the log's clock, where in its step the run's plant was at a frame is not in the log: a
position may be off by one plant step of the axis' motion beyond the tolerance.
"""

from __future__ import annotations

from hil.bus_config import DriveConfig
from hil.drives.profile import DriveProfile, Reading
from hil.replay.compare import UNITS, Answer, AnswerStream, Divergence, Tolerances, drive_units
from hil.replay.report import KEPT, Report
from hil.replay.rows import CycleRows
from hil.replay.seed import PlantSeed


class Judge:
    """Compares the pairs an answer stream has, into ``report``."""

    def __init__(self, drives: dict[tuple[int, int], tuple[DriveConfig, DriveProfile]],
                 actuator: dict[tuple[int, int], int], tolerances: Tolerances, report: Report,
                 seed: PlantSeed, rows: CycleRows, step: float):
        self._drives = drives
        self._actuator = actuator
        self._tolerances = tolerances
        self._report = report
        self._seed = seed
        self._rows = rows
        #: on the log's clock: the plant's step (s), by which a position may be off times
        #: its speed (0: on the cycles' clock); each drive's last logged speed (counts/s)
        self._step_slack = step
        self._speed: dict[tuple[int, int], float] = {}

    def compare(self, bus: int, node: int, stream: AnswerStream) -> None:
        """Every pair ``stream`` has now, of the drive ``node`` of ``bus``."""
        drive_config, drive = self._drives[bus, node]
        seed = self._seed
        for logged, replayed in stream.pairs():
            self._report.compared += 1
            same = logged.frame.data == replayed.frame.data
            expected = drive.readings(logged.frame)
            got = expected if same else drive.readings(replayed.frame)
            if not seed.placed and expected:
                seed.note(self._actuator[bus, node], expected)
            if self._step_slack and expected:
                for reading in expected:
                    if reading.quantity == "velocity":
                        self._speed[bus, node] = abs(drive_units(drive_config, reading))
            if (replayed.cycle >= seed.measured_from and expected is not None
                    and got is not None and len(expected) == len(got)):
                self._rows.add(self._actuator[bus, node], replayed.cycle, expected, got)
            if same:
                continue
            if expected is None or got is None or len(expected) != len(got):
                self.diverged(stream.divergence(logged, replayed, "bytes",
                                                logged.frame.data.hex(" "),
                                                replayed.frame.data.hex(" ")))
                continue
            for a, b in zip(expected, got):
                self._check(bus, stream, logged, replayed, drive_config, a, b)

    def _check(self, bus: int, stream: AnswerStream, logged: Answer, replayed: Answer,
               drive_config: DriveConfig, a: Reading, b: Reading) -> None:
        if a.value == b.value:
            return
        if replayed.cycle < self._seed.measured_from and a.quantity in UNITS:
            self._report.before_seed += 1   # the plant's state before the log: no one's
            return
        if a.quantity is None or (a.quantity == "derived" and self._tolerances.exact):
            self.diverged(stream.divergence(logged, replayed, a.name, f"{a.value:g}",
                                            f"{b.value:g}"))
        elif a.quantity == "derived":
            self._report.derived_unchecked += 1
        else:
            difference = abs(drive_units(drive_config, b) - drive_units(drive_config, a))
            tolerance = self._tolerances.of(drive_config, a.quantity)
            if a.quantity == "position" and self._step_slack:
                # where in its step the run's plant was is not in the log: a plant step of
                # the axis' motion (at its last logged speed) more
                tolerance += self._speed.get((bus, drive_config.node_id), 0.0) * self._step_slack
            if difference > tolerance:
                unit = UNITS[a.quantity]
                self.diverged(stream.divergence(
                    logged, replayed, a.name, f"{a.value:g}",
                    f"{b.value:g} ({difference:.3g} {unit} off, tolerance {tolerance:g})",
                    difference))

    def diverged(self, divergence: Divergence) -> None:
        """A divergence counted, and kept: among the first KEPT, or of the first cycle."""
        report = self._report
        report.divergence_count += 1
        report.by_drive[divergence.drive] = report.by_drive.get(divergence.drive, 0) + 1
        first = report.first
        if len(report.divergences) < KEPT or (first is not None
                                              and divergence.cycle <= first.cycle):
            report.divergences.append(divergence)
