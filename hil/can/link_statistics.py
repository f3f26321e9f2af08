"""What a ``zenoh`` CAN bus counts of its link: frames sent, received, lost, late, and the
link's round trip (see :mod:`hil.can.zenoh_bus`); and each sender's sequence numbers, whose
gaps are the frames lost."""

from __future__ import annotations

import math
from dataclasses import dataclass

#: how long a sender's quickest delivery stands as the base of its lateness (s)
QUICKEST_WINDOW = 10.0
#: a sender's sequence numbers are 32-bit and wrap: ``b`` is after ``a`` if
#: ``(b - a) & SEQUENCE_MASK`` is under SEQUENCE_HALF
SEQUENCE_MASK = 0xFFFFFFFF
SEQUENCE_HALF = 0x80000000
#: a sender's most recent gaps kept for a late message to fill
GAPS_KEPT = 32


@dataclass
class FrameCounters:
    """What a bus sent and received, and what it lost."""

    sent: int = 0
    received: int = 0
    #: frames other buses sent that never arrived here (gaps in their sequence numbers)
    lost: int = 0
    #: frames dropped because the receive FIFO was full (nobody read them in time)
    overrun: int = 0
    #: payloads on the channel that were not frames
    malformed: int = 0
    #: messages (frames sent together) put, and received
    messages_sent: int = 0
    messages_received: int = 0
    #: messages delivered over STALL_THRESHOLD later than their sender's quickest
    late: int = 0
    #: the latest of them (s beyond the quickest)
    latest: float = 0.0
    #: the link's round trip, from the echoes of this bus' messages (s): how many, the
    #: last, the least of the last SLOW_LINK_ECHOES (the link's floor now: one late echo
    #: is a hiccup of either end, every one of them late is the link), the least and the
    #: most
    round_trips: int = 0
    round_trip: float = math.nan
    round_trip_floor: float = math.nan
    round_trip_min: float = math.nan
    round_trip_max: float = math.nan

    def __str__(self) -> str:
        late = f", {self.late} delivered late (up to {self.latest * 1e3:.0f} ms)" \
            if self.late else ""
        link = (f", link round trip {self.round_trip_min * 1e3:.2f}-"
                f"{self.round_trip_max * 1e3:.2f} ms (last {self.round_trip * 1e3:.2f})"
                if self.round_trips else "")
        return (f"sent {self.sent} in {self.messages_sent} messages, received {self.received} "
                f"in {self.messages_received}, lost on the way {self.lost}, "
                f"overrun {self.overrun}, malformed {self.malformed}{late}{link}")

    def add_round_trip(self, seconds: float, floor: float) -> None:
        self.round_trips += 1
        self.round_trip, self.round_trip_floor = seconds, floor
        self.round_trip_min = min(self.round_trip_min, seconds) if self.round_trips > 1 \
            else seconds
        self.round_trip_max = max(self.round_trip_max, seconds) if self.round_trips > 1 \
            else seconds


class Quickest:
    """A sender's quickest arrival minus stamp (s): base latency plus the clocks' offset, which
    each message's own is held against. A sliding minimum, renewed every QUICKEST_WINDOW:
    unsynchronised clocks drift (50 ppm is 5 ms in 100 s), and an all-time minimum would
    turn a slow drift into late deliveries."""

    __slots__ = ("current", "next", "since")

    def __init__(self, current: float, next_: float, since: float):
        self.current, self.next, self.since = current, next_, since

    def lateness(self, transit: float, arrived: float) -> float:
        """How much later than the quickest this message came (s), the window updated."""
        if arrived - self.since > QUICKEST_WINDOW:
            self.current, self.next, self.since = self.next, transit, arrived
        elif transit < self.next:
            self.next = transit
        return transit - min(self.current, self.next)


class SenderSequences:
    """Each sender's last sequence number heard (:attr:`last`), and the gaps before it: its
    frames that never came, counted lost. A message that comes late, out of order, fills the
    gap it was counted in and is taken back off the lost count: it was not lost. (A local
    lock-step run's log counted one controller message lost, 4 frames a bus, where hil's
    assumption had been that Zenoh never reorders; a late message also set the sender's last
    number back, so that the next in-order message counted the frames between again.) At most
    GAPS_KEPT gaps a sender are kept."""

    def __init__(self) -> None:
        self.last: dict[int, int] = {}
        self._gaps: dict[int, list[tuple[int, int]]] = {}     # sender -> [(first, count)]

    def arrived(self, sender: int, sequence: int, frames: int) -> int:
        """A message of ``frames`` numbered from ``sequence``: by how many frames the lost
        count changes (the gap before it; minus the frames of a late one that fills a gap)."""
        last = self.last.get(sender)
        gap = 0 if last is None else (sequence - last - 1) & SEQUENCE_MASK
        if gap >= SEQUENCE_HALF:            # not after the last heard: late, or a repeat
            return -self._fill(sender, sequence, frames)
        self.last[sender] = (sequence + frames - 1) & SEQUENCE_MASK
        if gap and last is not None:
            gaps = self._gaps.setdefault(sender, [])
            gaps.append(((last + 1) & SEQUENCE_MASK, gap))
            del gaps[:-GAPS_KEPT]
        return gap

    def forget_oldest(self) -> int:
        """Forget the sender heard first (it is counted afresh if heard again); which."""
        oldest = next(iter(self.last))
        del self.last[oldest]
        self._gaps.pop(oldest, None)
        return oldest

    def _fill(self, sender: int, first: int, frames: int) -> int:
        """Take a late message's frames out of the gap that holds them all; how many."""
        gaps = self._gaps.get(sender, [])
        for k, (start, count) in enumerate(gaps):
            offset = (first - start) & SEQUENCE_MASK
            if frames and offset + frames <= count:
                rest = count - offset - frames
                gaps[k:k + 1] = [gap for gap in (
                    (start, offset), ((start + offset + frames) & SEQUENCE_MASK, rest)) if gap[1]]
                return frames
        return 0
