"""Which of the controller's faults the bench caused: drives found silent, held against the
stalls of the bench's own real-time processes (the simulator's, reported over Zenoh, and
the controller's own loop).

The controller still reacts to every fault as it must (quick stop, goal aborted): it is the
device under test and is told to ignore nothing. The attribution comes after, as a
diagnostic of its own, so that a user (and ``hil up``'s exit status) can tell a bench that
broke real time from a device that failed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from hil.hardware import AxisFault, FaultKind
from hil.protocols import names, protocol
from hil.realtime.stalls import PROCESS_WORDS, Stall, clock_time

#: how long a fault waits for stalls that explain it before it is attributed (s): another
#: process reports its stall once it has ended, after the silence it caused was found
GRACE = 1.0
#: how long a fault or a stall is kept for matching (s)
RETAIN = 5.0
#: slack for the clocks' readings around when a silence began (s)
MARGIN = 0.005


def link_loss_codes() -> frozenset[int]:
    """The error codes with which a drive says it lost its master's frames, as each protocol
    hil knows declares them (:attr:`hil.protocols.base.Protocol.link_loss_codes`; CiA 402:
    its RPDO timeout and heartbeat consumer EMCYs): a stall of the controller, of the
    transport or of the simulator's own clock can trip those watchdogs as it can a
    silence."""
    return frozenset().union(*(protocol(name).link_loss_codes for name in names()))


def stalls_in_words(stalls: Sequence[Stall]) -> list[str]:
    """Each process' stalls (oldest first): one in full, several (a burst of late messages)
    in a line."""
    words = []
    for process in dict.fromkeys(stall.process for stall in stalls):
        own = [stall for stall in stalls if stall.process == process]
        if len(own) == 1:
            words.append(str(own[0]))
            continue
        where = ", ".join(dict.fromkeys(stall.where for stall in own if stall.where))
        first = clock_time(own[0].at)
        longest = max(stall.length for stall in own)
        what = {"transport": f"delivered {len(own)} messages late",
                "link": f"was slow {len(own)} times, round trips"}.get(
                    process, f"stalled {len(own)} times")
        words.append(f"{PROCESS_WORDS.get(process, process)} {what} from {first}, up to "
                     f"{longest * 1e3:.0f} ms" + (f" ({where})" if where else ""))
    return words


@dataclass(frozen=True)
class Attribution:
    """Faults explained by stalls of the bench (oldest first)."""

    stalls: tuple[Stall, ...]
    faults: tuple[AxisFault, ...]

    def message(self) -> str:
        drives = ", ".join(f"{f.bus}/{f.node_id}" for f in self.faults)
        return (f"bench fault, not a drive fault: {'; '.join(stalls_in_words(self.stalls))}; "
                f"{'it explains' if len(self.stalls) == 1 else 'they explain'} the "
                f"{len(self.faults)} drive fault(s) of lost frames ({drives})")

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
    """Holds faults that losing frames causes against stalls. A drive found silent, and a
    drive that reported losing its master's frames (:func:`link_loss_codes`, where
    ``link_timeouts`` gives its watchdog time), can be the bench's. A stall explains such a
    fault if it was under way when the drive's silence began (found at ``t`` after the drive
    had not answered for its ``silent_for``, or ``silence_cycles`` of ``period``; for a lost
    link, its watchdog time before the EMCY was read) and lasted at least two cycles (a lost
    link: at least half its watchdog time): a stall that comes later, such as the
    controller's own work of reporting the fault, or a short one inside a long silence, is
    no cause. Not thread-safe: the control loop feeds and asks it."""

    def __init__(self, period: float, silence_cycles: int,
                 link_timeouts: dict[tuple[str, int], float] | None = None):
        self.period = period
        self.window = silence_cycles * period
        self.link_timeouts = dict(link_timeouts or {})
        self.link_loss_codes = link_loss_codes()
        # (when its silence began, found, the fault, the shortest stall that can cause it)
        self._faults: list[tuple[float, float, AxisFault, float]] = []
        self._stalls: list[Stall] = []

    @property
    def waiting(self) -> bool:
        """Whether a fault waits for its explanation."""
        return bool(self._faults)

    def settled_at(self) -> float:
        """When every waiting fault has had its GRACE (wall time; -inf if none waits)."""
        return max((found_at + GRACE for _, found_at, _, _ in self._faults), default=-math.inf)

    def fault(self, fault: AxisFault, wall: float) -> None:
        """A fault found at ``wall`` (s since the epoch); only losses of frames can be the
        bench's."""
        if fault.kind is FaultKind.SILENT:
            silence = fault.silent_for if fault.silent_for is not None else self.window
            self._faults.append((wall - silence, wall, fault, 2 * self.period))
            return
        timeout = self.link_timeouts.get((fault.bus, fault.node_id))
        if fault.code in self.link_loss_codes and timeout is not None:
            self._faults.append((wall - timeout, wall, fault, timeout / 2))

    def stall(self, stall: Stall) -> None:
        self._stalls.append(stall)

    def attributions(self, wall: float) -> list[Attribution]:
        """The faults found GRACE or more before ``wall`` and explained by stalls, in one
        attribution with every stall that explains any of them (none: an empty list);
        forgets what is too old."""
        stalls_found: dict[Stall, None] = {}
        faults_found: list[AxisFault] = []
        waiting = []
        for entry in self._faults:
            began, found_at, fault, shortest = entry
            stalls = tuple(sorted((s for s in self._stalls
                                   if self._explains(s, began, shortest)), key=lambda s: s.at))
            if wall - found_at < GRACE:
                waiting.append(entry)
            elif stalls:
                stalls_found.update(dict.fromkeys(stalls))
                faults_found.append(fault)
            elif wall - found_at < RETAIN:
                waiting.append(entry)
        self._faults = waiting
        self._stalls = [s for s in self._stalls if wall - s.end < RETAIN]
        if not faults_found:
            return []
        return [Attribution(tuple(sorted(stalls_found, key=lambda s: s.at)),
                            tuple(faults_found))]

    @staticmethod
    def _explains(stall: Stall, began: float, shortest: float) -> bool:
        return (stall.length >= shortest
                and stall.at - stall.resolution <= began + MARGIN
                and stall.end >= began - MARGIN)
