"""Events in a recording: a real-time process' stalls (``loop/stalls/<process>``, a row an
interval per process: :mod:`.stall_digest`) and the controller's faults and resets
(``diagnostics``, a text log), each at the time it happened."""

from __future__ import annotations

import numpy as np
import rerun as rr

from hil.messaging.diagnostics import DiagnosticStatus
from hil.realtime.stalls import PROCESS_WORDS, Stall
from hil.visualisation.columns import ScalarTable
from hil.visualisation.entities import RobotEntities
from hil.visualisation.stall_digest import StallDigest, StallRow

#: diagnostic levels as rerun's text log levels
_TEXT_LOG_LEVELS = {"OK": rr.TextLogLevel.INFO, "WARN": rr.TextLogLevel.WARN,
                    "ERROR": rr.TextLogLevel.ERROR, "STALE": rr.TextLogLevel.WARN}


class EventLog:
    """A robot's stalls and diagnostics; ``stalls_logged`` counts the stalls taken."""

    def __init__(self, entities: RobotEntities):
        self._entities = entities
        self._stalls = StallDigest()
        self.stalls_logged = 0

    def log_static(self) -> None:
        for process, words in PROCESS_WORDS.items():     # points: a stall is an event
            self._entities.recording.log(
                f"{self._entities.root}/loop/stalls/{process}", rr.SeriesPoints(
                    names=[f"{words} stalled [ms], the second's worst",
                           f"{words} stalls that second"],
                    markers=["cross", "circle"], marker_sizes=[6.0, 3.0]), static=True)

    def diagnostic(self, diagnostic: DiagnosticStatus) -> None:
        """A fault (ERROR) or reset (OK) on the timelines, at the time the controller saw it."""
        control = None if diagnostic.control_time is None else np.array([diagnostic.control_time])
        times = self._entities.times(np.array([diagnostic.wall_time]), control)
        self._entities.recording.send_columns(
            f"{self._entities.root}/diagnostics", indexes=times.columns(),
            columns=rr.TextLog.columns(text=[diagnostic.message],
                                       level=[_TEXT_LOG_LEVELS[diagnostic.level]]))

    def stall(self, stall: Stall) -> None:
        """A stall: gathered, a row an interval per process at the worst's start on the wall
        and sim timelines."""
        self.stalls_logged += 1
        self._send(self._stalls.add(stall))

    def due(self, now: float) -> None:
        """The rows of the intervals ended by ``now`` (a quiet process' last interval)."""
        self._send(self._stalls.due(now))

    def drain(self) -> None:
        """Every row still gathering (the recording's end or a segment's)."""
        self._send(self._stalls.drain())

    def _send(self, rows: list[StallRow]) -> None:
        for row in rows:
            table = ScalarTable(self._entities.times(np.array([row.at])))
            table.add(f"{self._entities.root}/loop/stalls/{row.process}",
                      np.array([row.worst * 1e3]), np.array([float(row.count)]))
            table.send(self._entities.recording)
