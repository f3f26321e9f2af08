"""A ``zenoh`` CAN bus' account of its link (:mod:`hil.can.zenoh_bus` owns one): each
message's arrival counted per sender, its lateness, and the link's round trip.

Each section carries the sender's clock at the put, so a receiver tells a late sender
from a slow delivery: a message over STALL_THRESHOLD later than the quickest of that
sender's (of the last 10 to 20 s, as clocks drift; so across hosts too) is a
:class:`~hil.realtime.stalls.Stall` of the transport. Each section also echoes the message
its sender heard last and how long it held it, as an RTCP receiver report does: the echoed
sender takes its own put time and the hold out of the arrival and has the link's round trip
on its own clock (:attr:`FrameCounters.round_trip`; a drive's answer echoes the master's
SYNC). SLOW_LINK_ECHOES of them in a row over STALL_THRESHOLD are a
:class:`~hil.realtime.stalls.Stall` of the link, the cause of the silence a slow link makes
of every drive on it.

This is the receive path of every Zenoh message: the account makes nothing per frame, and
per message what the counts need (a stall only when there is one).
"""

from __future__ import annotations

import collections
import threading

from hil.can.link_statistics import SEQUENCE_MASK, FrameCounters, Quickest, SenderSequences
from hil.can.zenoh_wire import NO_ECHO, Echo, Message
from hil.realtime.stalls import STALL_THRESHOLD, Stall

#: senders a bus remembers (sequence numbers, quickest delivery) before it forgets the
#: oldest: a bus has a handful; a flood of made-up sender ids must not grow the memory
MAX_SENDERS = 1024
#: put times kept for echoes to be matched with (messages)
PUTS_KEPT = 1024
#: a link is slow when this many round trips in a row are over STALL_THRESHOLD
SLOW_LINK_ECHOES = 4


class LinkAccount:
    """What the bus of ``sender`` (its id on the wire) on channel ``where`` counts of its
    link: :attr:`counters`, each sender's numbers heard (:meth:`heard`), and the stalls
    of the transport and the link. Zenoh delivers from a thread per link, and a bus sends
    from any thread: the counts of arrivals are taken under a lock; those of sends under
    the session's send lock, which the bus holds."""

    def __init__(self, sender: int, where: str) -> None:
        self._sender = sender
        self._where = where
        self.counters = FrameCounters()
        self._lock = threading.Lock()
        self._sequences = SenderSequences()    # each sender's last number heard, its gaps
        self._quickest: dict[int, Quickest] = {}
        # the last message heard (sender, first sequence, monotonic arrival): echoed
        self._last_heard: tuple[int, int, float] | None = None
        self._puts: dict[int, float] = {}    # first sequence -> monotonic put time
        self._recent_trips: collections.deque[float] = collections.deque(
            maxlen=SLOW_LINK_ECHOES)
        self._link_stall_end = 0.0            # when the link stall reported last ended

    def heard(self) -> dict[int, int]:
        """Each sender's last sequence number heard."""
        with self._lock:
            return dict(self._sequences.last)

    def sent(self, first: int, frames: int, now: float) -> Echo:
        """A message of ``frames`` numbered from ``first``, put at ``now`` (monotonic):
        counted, and its put time kept for the echo of it; what it echoes (the message
        heard last)."""
        counters = self.counters
        counters.sent += frames
        counters.messages_sent += 1
        heard = self._last_heard
        # heard after ``now`` was read (another thread): held 0 s; a negative hold is malformed
        echo = NO_ECHO if heard is None else Echo(heard[0], heard[1], max(0.0, now - heard[2]))
        puts = self._puts
        puts[first & SEQUENCE_MASK] = now
        if len(puts) > PUTS_KEPT:
            del puts[next(iter(puts))]       # the oldest
        return echo

    def arrived(self, message: Message, arrived: float, now: float) -> tuple[Stall, ...]:
        """A message from Zenoh, arrived at ``arrived`` (wall clock) and ``now``
        (monotonic): counted, remembered to be echoed; the stalls it ends (none, usually)."""
        self._last_heard = (message.sender, message.sequence, now)
        transport = self.count(message.sender, message.sequence, len(message.frames),
                               arrived - message.sent_at, arrived)
        link = self._round_trip(message.echo, now, arrived)
        if transport is None and link is None:
            return ()
        return tuple(stall for stall in (transport, link) if stall is not None)

    def count(self, sender: int, sequence: int, frames: int, transit: float,
              arrived: float) -> Stall | None:
        """Counts a message of ``frames`` from ``sender``; the transport's stall if it came
        late. (A bus of this process hands its frames over with transit 0: never late.)"""
        counters = self.counters
        with self._lock:
            counters.received += frames
            counters.messages_received += 1
            if sender not in self._sequences.last and len(self._sequences.last) >= MAX_SENDERS:
                # a bounded memory of senders (each message may claim a new one)
                self._quickest.pop(self._sequences.forget_oldest(), None)
            counters.lost += self._sequences.arrived(sender, sequence, frames)
            quickest = self._quickest.get(sender)
            if quickest is None:
                self._quickest[sender] = Quickest(transit, transit, arrived)
                return None
            late = quickest.lateness(transit, arrived)
            if not late > STALL_THRESHOLD:
                return None
            counters.late += 1
            counters.latest = max(counters.latest, late)
        return Stall("transport", arrived - late, late, where=self._where)

    def overrun(self) -> None:
        """A frame dropped: the receive FIFO was full."""
        with self._lock:
            self.counters.overrun += 1

    def malformed(self) -> int:
        """A payload that was not a message: counted; how many so far."""
        with self._lock:
            self.counters.malformed += 1
            return self.counters.malformed

    def _round_trip(self, echo: Echo, now: float, arrived: float) -> Stall | None:
        """The link's round trip, if ``echo`` is of a message of this bus; a stall of the
        link while its floor (SLOW_LINK_ECHOES round trips in a row) is over
        STALL_THRESHOLD, one per stretch of them (a slow link would otherwise report each
        of its messages; a single late echo is a hiccup of an end, which the processes'
        and the transport's own accounting report)."""
        if echo.sender != self._sender:
            return None
        put = self._puts.get(echo.sequence)
        if put is None:
            return None
        round_trip = max(0.0, now - put - echo.held)
        with self._lock:
            recent = self._recent_trips
            recent.append(round_trip)
            floor = min(recent)
            self.counters.add_round_trip(round_trip, floor)
            # a stall covers this message's round trip: the next begins after it ends
            if (len(recent) < SLOW_LINK_ECHOES or not floor > STALL_THRESHOLD
                    or arrived - round_trip < self._link_stall_end):
                return None
            self._link_stall_end = arrived
        return Stall("link", arrived - round_trip, round_trip, where=self._where)
