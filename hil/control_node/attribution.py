"""Which of the controller's faults the bench caused: drives found silent, held against the
stalls of the bench's own real-time processes (the simulator's, reported over Zenoh, and
the controller's own loop).

The controller still reacts to every fault as it must (quick stop, goal aborted): it is the
device under test and is told to ignore nothing. The attribution comes after, as a
diagnostic of its own, so that a user (and ``hil up``'s exit status) can tell a bench that
broke real time from a device that failed.
"""

from __future__ import annotations

from dataclasses import dataclass

from hil.hardware import AxisFault, FaultKind
from hil.realtime.stalls import Stall

#: how long a fault waits for stalls that explain it before it is attributed (s): another
#: process reports its stall once it has ended, after the silence it caused was found
GRACE = 1.0
#: how long a fault or a stall is kept for matching (s)
RETAIN = 5.0
#: slack for the clocks' readings around when a silence began (s)
MARGIN = 0.005


@dataclass(frozen=True)
class Attribution:
    """Faults explained by stalls of the bench (oldest first)."""

    stalls: tuple[Stall, ...]
    faults: tuple[AxisFault, ...]

    def message(self) -> str:
        drives = ", ".join(f"{f.bus}/{f.node_id}" for f in self.faults)
        return (f"bench fault, not a drive fault: {'; '.join(map(str, self.stalls))}; "
                f"{'it explains' if len(self.stalls) == 1 else 'they explain'} the "
                f"{len(self.faults)} drive(s) reported silent ({drives})")

    def values(self) -> tuple[tuple[str, str], ...]:
        """As diagnostic KeyValues: kind bench_stall, the stalls (comma-separated, in turn)
        and the faults they explain."""
        def each(value) -> str:
            return ",".join(value(stall) for stall in self.stalls)
        return (("kind", "bench_stall"), ("process", each(lambda s: s.process)),
                ("at", each(lambda s: repr(s.at))),
                ("stall_ms", each(lambda s: f"{s.length * 1e3:.1f}")),
                ("steal_ms", each(lambda s: f"{s.steal * 1e3:.1f}")),
                ("explains", str(len(self.faults))),
                ("drives", ",".join(f"{f.bus}/{f.node_id}" for f in self.faults)))


class FaultAttribution:
    """Holds silent drives against stalls. A stall explains a silence if it lasted at least
    two cycles and was under way when the silence began (found at ``t`` after the drive had
    not answered for its ``silent_for``, or ``silence_cycles`` of ``period``): a stall that
    comes later, such as the controller's own work of reporting the fault, or a short one
    inside a long silence, is no cause. Not thread-safe: the control loop feeds and asks
    it."""

    def __init__(self, period: float, silence_cycles: int):
        self.period = period
        self.window = silence_cycles * period
        self._faults: list[tuple[float, AxisFault]] = []
        self._stalls: list[Stall] = []

    @property
    def waiting(self) -> bool:
        """Whether a fault waits for its explanation."""
        return bool(self._faults)

    def fault(self, fault: AxisFault, wall: float) -> None:
        """A fault found at ``wall`` (s since the epoch); only silences can be the bench's."""
        if fault.kind is FaultKind.SILENT:
            self._faults.append((wall, fault))

    def stall(self, stall: Stall) -> None:
        self._stalls.append(stall)

    def attributions(self, wall: float) -> list[Attribution]:
        """The faults found GRACE or more before ``wall`` and explained by stalls (every
        stall that explains each), grouped by those stalls; forgets what is too old."""
        found: dict[tuple[Stall, ...], list[AxisFault]] = {}
        waiting = []
        for found_at, fault in self._faults:
            began = found_at - (fault.silent_for if fault.silent_for is not None
                                else self.window)
            stalls = tuple(sorted((s for s in self._stalls if self._explains(s, began)),
                                  key=lambda s: s.at))
            if wall - found_at < GRACE:
                waiting.append((found_at, fault))
            elif stalls:
                found.setdefault(stalls, []).append(fault)
            elif wall - found_at < RETAIN:
                waiting.append((found_at, fault))
        self._faults = waiting
        self._stalls = [s for s in self._stalls if wall - (s.at + s.length) < RETAIN]
        return [Attribution(stalls, tuple(faults)) for stalls, faults in found.items()]

    def _explains(self, stall: Stall, began: float) -> bool:
        return (stall.length >= 2 * self.period
                and stall.at - stall.resolution <= began + MARGIN
                and stall.at + stall.length >= began - MARGIN)
