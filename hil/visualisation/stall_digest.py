"""Stalls in a recording at a bounded cost: per process, one row an interval, the worst.

A loaded host stalls a real-time process thousands of times in a run; a point for each
(rerun keeps an index entry per chunk) grew a recording past its byte budget. Each
process' stalls are gathered over STALL_INTERVAL of wall time from the first: one row then,
at the worst stall's start, its length and how many stalls the interval held.
"""

from __future__ import annotations

from dataclasses import dataclass

from hil.realtime.stalls import Stall

#: the stalls of one process within this many seconds make one row
STALL_INTERVAL = 1.0


@dataclass(frozen=True)
class StallRow:
    """One row of ``loop/stalls/<process>``: the interval's worst stall and its count."""

    process: str
    at: float                 # wall time the worst stall began (s)
    worst: float              # its length (s)
    count: int


class StallDigest:
    """The stalls not yet logged, by process (:meth:`add`, :meth:`due`, :meth:`drain`)."""

    def __init__(self, interval: float = STALL_INTERVAL):
        self.interval = interval
        self._pending: dict[str, tuple[float, StallRow]] = {}    # process -> (first, row)

    def add(self, stall: Stall) -> list[StallRow]:
        """Take a stall; the rows whose interval it ends (to log now)."""
        rows = self.due(stall.at)
        first, row = self._pending.get(stall.process, (stall.at, None))
        if row is None or stall.length > row.worst:
            row = StallRow(stall.process, stall.at, stall.length,
                           1 if row is None else row.count + 1)
        else:
            row = StallRow(row.process, row.at, row.worst, row.count + 1)
        self._pending[stall.process] = (first, row)
        return rows

    def due(self, now: float) -> list[StallRow]:
        """The rows whose interval has ended by ``now``."""
        ended = [process for process, (first, _) in self._pending.items()
                 if now - first >= self.interval]
        return [self._pending.pop(process)[1] for process in ended]

    def drain(self) -> list[StallRow]:
        """Every row still gathering (a segment's or the run's end)."""
        rows = [row for _, row in self._pending.values()]
        self._pending.clear()
        return rows
