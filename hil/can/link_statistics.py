"""What a ``zenoh`` CAN bus counts of its link: frames sent, received, lost, late, and the
link's round trip (see :mod:`hil.can.zenoh_bus`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

#: how long a sender's quickest delivery stands as the base of its lateness (s)
QUICKEST_WINDOW = 10.0


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
