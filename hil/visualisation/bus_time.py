"""Bus loads per second of bus time.

The monitor measures each bus per second of wall time. A lock-step run is not on the
wall's clock: its buses carry a control cycle's frames as fast as the sim steps, 2-4
cycles of bus time per wall period, and a wall-time load overstates what the same traffic
takes on a real bus by that much (190 % where `hil check` says 72 %). The controller's
clock is the bus's: every cycle of it sends one cycle's frames. So a row measured over
[w0, w1] of wall time (rows merged over WINDOW) is its bits over the cycles the controller
ran in it x its period, counted from the recorded cycles' wall times. A row waits until cycles past
its end have been recorded; without a controller (its cycles not recorded for
CLOCKLESS s) the wall's seconds stand.
"""

from __future__ import annotations

import numpy as np

#: a row waits at most this long (s of wall time) for the controller's cycles to cover it
CLOCKLESS = 2.0
#: rows merge into one over this long at least (s of wall time): a cycle's frames straddle
#: a short row's edges, and a loaded host's lock-step pace varies from row to row
WINDOW = 0.5
#: the cycles' wall times kept (s): more than a row waits
KEPT = 2 * CLOCKLESS


class BusTimeLoads:
    """Bus-load rows measured on the wall clock, handed out on the bus's clock."""

    def __init__(self):
        #: the recorded cycles' wall times (the last KEPT s of them) and their period
        self._walls = np.empty(0)
        self._period = 0.0
        self._pending: list[tuple[float, float, list[float]]] = []   # (w0, w1, row)

    def cycles(self, wall: np.ndarray, period: float) -> None:
        """Recorded cycles: the wall time of each, and the control period."""
        self._walls = np.concatenate((self._walls, wall))
        self._walls = self._walls[self._walls >= self._walls[-1] - KEPT]
        self._period = period

    def add(self, start: float, end: float, row: list[float]) -> None:
        self._pending.append((start, end, row))

    def ready(self, now: float, final: bool = False) -> tuple[list[float], list[list[float]]]:
        """(end times, rows) that can go: the rows covered by recorded cycles merged into
        one a WINDOW at least (less once they waited CLOCKLESS, or at ``final``, the run's
        end), its bits over its bus time; rows no cycle covers once they waited CLOCKLESS
        (or at ``final``) on wall time."""
        covered = self._walls[-1] if len(self._walls) else -np.inf
        times, rows = [], []
        while self._pending:
            start, end, row = self._pending[0]
            # at the end, the covered rows first: merged with the tail past the last cycle
            # (a visualiser's last row, up to its stop) they would be diluted by it
            group = [item for item in self._pending if item[1] <= covered] or (
                self._pending if final else [])
            span = group[-1][1] - start if group else 0.0
            waited = now - end > CLOCKLESS
            if start < end and group and (span >= WINDOW or final or waited) and covered > start:
                self._pending = self._pending[len(group):]
                bus = self._bus_seconds(start, group[-1][1])
                weights = np.array([b - a for a, b, _ in group])
                merged = weights @ np.array([r for _, _, r in group]) / bus if bus > 0 \
                    else np.array(row)
                times.append(group[-1][1])
                rows.append(merged.tolist())
            elif final or start >= end or waited:        # no cycles to it, or no interval said
                self._pending.pop(0)
                times.append(end)
                rows.append(row)
            else:
                break
        return times, rows

    def _bus_seconds(self, start: float, end: float) -> float:
        """The bus time of [start, end]: the cycles the controller ran in it, and the wall's
        own seconds outside the cycles' run (before the first, after the last: no
        controller, the bus on wall time)."""
        walls = self._walls
        cycles = np.searchsorted(walls, end) - np.searchsorted(walls, start)
        outside = max(0.0, min(end, walls[0]) - start) + max(0.0, end - max(start, walls[-1]))
        return cycles * self._period + outside
