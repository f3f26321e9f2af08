"""Watching a bus as an analyser does: every frame on it, counted in bits.

A :class:`BusLoadMeter` is a python-can ``Listener``: give it to a
``can.Notifier`` together with a ``can.Logger`` and the same buses, and it
measures what the logger records.
"""

from __future__ import annotations

import heapq
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import can

from hil.can.capabilities import capabilities
from hil.can.frames import BitRates, fd_frame_bits, frame_bits
from hil.can.messages import received_copy


@dataclass(frozen=True)
class MeasuredLoad:
    """One bus over one interval: frames per second and load as a fraction of the bitrate."""

    bus: str
    frames_per_second: float
    nominal: float            # without stuff bits
    worst_case: float         # with worst-case bit stuffing
    interval: float = 0.0     # s of wall time measured (0: not said)


#: a stamped meter's rows end this long (s) before the wall's now: the frames of a row's
#: interval have reached it by then though the monitor (idle priority) was starved that long
STAMPED_LAG = 0.5
#: a frame stamped further (s) from its arrival is on another clock (a replayed log's, a host
#: far off this one's): counted on arrival. Not from a source: wider than any lag above
SAME_CLOCK = 2.0
#: frames a stamped meter holds for their interval at most; beyond, the oldest are counted
#: (memory bounded where nobody takes the load)
MAX_PENDING = 200_000


class BusLoadMeter(can.Listener):
    """Counts frames and bits per bus; :meth:`take` gives the load since the last call.

    ``channels`` maps each bus' python-can channel to (bus name, its bit rates); frames
    are told apart by ``Message.channel``. An FD frame with the bit-rate switch is counted
    with its data phase at the bus' data rate, as ``hil check`` estimates it
    (:func:`hil.can.frames.bus_load`).

    ``by_timestamp``: a frame is counted in the interval its timestamp falls in, not the
    one it reached the meter in, and a caller ends its rows :attr:`lag` s before now. For a
    monitor whose buses stamp frames with their senders' clock (``hil viz``): it runs at
    idle priority, and on a loaded host heard a lock-step run's frames in bursts, rows of
    48-134 % where the bus carried 91 % (CI, tests/test_openarm.py).
    """

    def __init__(self, channels: dict[str, tuple[str, BitRates]], now: float,
                 by_timestamp: bool = False):
        self._buses = {str(channel): name for channel, (name, _) in channels.items()}
        self._counts = {name: [0, 0, 0] for name, _ in channels.values()}
        self._rates = dict(channels.values())
        self._since = now
        self._lock = threading.Lock()
        self._by_timestamp = by_timestamp
        #: (timestamp, bus, nominal bits, worst-case bits) of frames past the last interval
        self._pending: list[tuple[float, str, int, int]] = []
        #: how long before now a caller's :meth:`take` ends its interval (the frames of a
        #: window have arrived by then)
        self.lag = STAMPED_LAG if by_timestamp else 0.0
        self.unknown_channel_frames = 0

    def on_message_received(self, msg: can.Message) -> None:
        if msg.is_error_frame:
            return
        bus = self._buses.get(str(msg.channel))
        if bus is None:
            self.unknown_channel_frames += 1
            return
        if msg.is_fd:
            nominal, worst = fd_frame_bits(len(msg.data), msg.is_extended_id,
                                           self._rates[bus].data_ratio(msg.bitrate_switch))
        else:
            nominal, worst = frame_bits(0 if msg.is_remote_frame else len(msg.data),
                                        msg.is_extended_id)
        stamped = self._by_timestamp and abs(msg.timestamp - time.time()) < SAME_CLOCK
        with self._lock:
            if stamped and msg.timestamp > self._since:
                heapq.heappush(self._pending, (msg.timestamp, bus, nominal, worst))
                if len(self._pending) > MAX_PENDING:
                    self._count(*heapq.heappop(self._pending)[1:])
            else:                          # its interval's turn: the next take counts it
                self._count(bus, nominal, worst)

    def _count(self, bus: str, nominal: int, worst: int) -> None:
        counts = self._counts[bus]
        counts[0] += 1
        counts[1] += nominal
        counts[2] += worst

    def take(self, until: float) -> list[MeasuredLoad]:
        """Each bus' load from the last call's end to ``until`` (the wall clock's s)."""
        with self._lock:
            while self._pending and self._pending[0][0] <= until:
                self._count(*heapq.heappop(self._pending)[1:])
            counts, self._counts = self._counts, {name: [0, 0, 0] for name in self._counts}
            interval, self._since = until - self._since, max(self._since, until)
        if interval <= 0:
            return []
        return [MeasuredLoad(bus, frames / interval,
                             nominal / interval / self._rates[bus].nominal,
                             worst / interval / self._rates[bus].nominal, interval)
                for bus, (frames, nominal, worst) in counts.items()]


#: log formats that number their channels (1, 2, ...) where hil's are names
NUMBERED_CHANNELS = (".blf", ".asc", ".trc")


class NumberedChannels(can.Listener):
    """Passes each frame on to a log writer with its channel's number instead of its name
    (BLF, ASC and TRC store a number; python-can's writers read a name's trailing digits as
    one, or put it on 1), every other field of the frame kept."""

    def __init__(self, writer: can.Listener, numbers: dict[str, int]):
        self._writer, self._numbers = writer, numbers

    def on_message_received(self, msg: can.Message) -> None:
        # a copy, FD, BRS and ESI kept: python-can's writers number a named channel by its
        # trailing digits (can.util.channel2int), and BLF's channel is 16 bits, so a channel
        # named "toy/6b754898" stopped the writer's thread with struct.error
        self._writer.on_message_received(received_copy(
            msg, msg.timestamp, self._numbers.get(str(msg.channel), 0), msg.is_rx))

    def stop(self) -> None:
        self._writer.stop()


class BusMonitor:
    """Listens to buses opened for monitoring: measures their load and optionally writes
    every frame to a python-can log file (format by suffix: .blf is Vector's binary log,
    .log candump's, .asc, .csv, .trc ...). Where the format numbers channels, each bus is
    numbered in the order given (``channel_numbers``). ``by_timestamp``: its meter counts
    each frame by its timestamp (:class:`BusLoadMeter`), for buses that stamp frames with
    their senders' clocks."""

    def __init__(self, buses: dict[str, can.BusABC], channels: dict[str, str],
                 bit_rates: dict[str, BitRates], log_path=None, now: float | None = None,
                 by_timestamp: bool = False):
        self.buses = buses
        self.meter = BusLoadMeter({channels[name]: (name, bit_rates[name]) for name in buses},
                                  time.time() if now is None else now, by_timestamp)
        #: bus name -> its channel number in the log (formats that number them), else empty
        self.channel_numbers: dict[str, int] = {}
        self.logger = None
        if log_path is not None:
            self.logger = can.Logger(log_path)
            if Path(log_path).suffix.lower() in NUMBERED_CHANNELS:
                self.channel_numbers = {name: k + 1 for k, name in enumerate(buses)}
                self.logger = NumberedChannels(self.logger, {
                    str(channels[name]): number for name, number in self.channel_numbers.items()})
        listeners = [self.meter] + ([self.logger] if self.logger is not None else [])
        # a bus that delivers in its own thread (hil-virtual, zenoh) hands every frame to the
        # log as it comes: a Notifier reads a bounded receive FIFO, which a controller's
        # burst of SDO configuration (30,000 frames/s for a second) overran, the monitor
        # running at idle priority, and the log lost frames
        self._direct, queued = [], []
        for bus in buses.values():
            delivery = capabilities(bus).deliver_to(listeners)
            if delivery is not None:
                self._direct.append(delivery)
            else:
                queued.append(bus)
        self._notifier = can.Notifier(queued, listeners, timeout=0.1) if queued else None

    def received(self) -> int:
        """Frames received so far on the buses that count them (hil-virtual, zenoh)."""
        counted = (capabilities(bus).counters for bus in self.buses.values())
        return sum(counters.received for counters in counted if counters is not None)

    def close(self) -> None:
        """Stop listening, close the log (flushed) and the buses."""
        for delivery in self._direct:
            delivery.stop(1.0)
        if self._notifier is not None:
            self._notifier.stop(1.0)            # stops its listeners: the log among them
        elif self.logger is not None:
            self.logger.stop()
        for bus in self.buses.values():
            bus.shutdown()
