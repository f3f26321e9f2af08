"""A python-can interface that carries CAN frames over Zenoh.

Registered as python-can interface ``zenoh`` (entry point group
``can.interface``), so ``can.Bus(interface="zenoh", channel="ur3/arm")``
works in any program. Every bus on the same channel, in any process that
reaches the same Zenoh network, sees every frame the others send, in order
per sender, like a CAN bus; a bus does not receive its own frames unless
``receive_own_messages=True``. There is no arbitration or bandwidth limit:
``hil check`` estimates the load a real bus would carry.

Why: SocketCAN ``vcan`` needs a Linux kernel with CAN; python-can's
``virtual`` bus is one process only and ``udp_multicast`` sends to the
network. Zenoh over loopback TCP is cross-process, loopback-only by default,
and also lets a bench put drives and controller on different hosts.

Back-pressure, as a CAN controller has it: a send never blocks its thread (a drive answers
from inside a delivery, holding the simulator's lock): under congestion Zenoh drops the
frame (``CongestionControl.DROP``, after at most ``hil.zenoh_session.DROP_WAIT_US``).
Frames reach other processes only (``Locality.REMOTE``); buses of one process that share a
Zenoh session hand each other their frames in the sender's thread, as ``hil-virtual``
does. So a bus' own frames never enter the channel of its Zenoh callback, which only the
thread that answers inside that callback drains (a drive answering into its own full
channel locked `hil sim` up for good under 20,000 SDO requests/s). One subscriber per
session takes the frames of every channel (``hil/can/**``) and hands them to the buses on
it: one Python thread for all of a process' buses (with a thread per bus, a simulator's two
buses fought for the GIL at every SYNC). That thread is fed by a channel (``indirect``): run
in Zenoh's receiving thread instead, every frame took the GIL there, and a cycle's round
trip between two processes doubled (630 -> 1140 us p50, measured). Received frames go to a bounded FIFO for
``recv`` (a full one drops and counts them: an overrun), or, after ``deliver_to``
(:mod:`hil.can.delivery`), straight to the listeners. Every frame carries its sender's
sequence number, so a receiver counts what was lost on the way (:class:`FrameCounters`).

Wire format of one frame (little-endian): sender id u64, sequence number u32 (per
sender, wrapping), arbitration id u32, flags u8 (1 extended, 2 remote, 4 error), DLC u8,
then the data bytes.
"""

from __future__ import annotations

import logging
import os
import queue
import random
import struct
import threading
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path

import can
import zenoh

from hil.can.delivery import DirectDelivery
from hil.can.messages import received_copy
from hil.zenoh_session import ZenohSettings, session

log = logging.getLogger(__name__)

KEY_PREFIX = "hil/can/"
_HEADER = struct.Struct("<QIIBB")
_SENDER = struct.Struct("<Q")
_EXTENDED, _REMOTE, _ERROR = 1, 2, 4
#: frames a bus holds for ``recv`` before it drops new ones (a CAN controller's RX FIFO)
RECEIVE_FIFO = 8192
#: a malformed payload is logged the first time, then every this many
LOG_EVERY = 1000


class _Channels:
    """A session's CAN channels: the buses of this process on each key, fed by the one
    subscriber of the session (and by each other)."""

    _of_session: dict[int, _Channels] = {}
    _lock = threading.Lock()

    def __init__(self, session: zenoh.Session):
        self.buses: dict[str, list[ZenohBus]] = {}
        self._subscriber = session.declare_subscriber(
            KEY_PREFIX + "**", self._on_sample, allowed_origin=zenoh.Locality.REMOTE)

    @classmethod
    def join(cls, session: zenoh.Session, key: str, bus: ZenohBus) -> list[ZenohBus]:
        """Add ``bus`` on ``key``; returns the buses of this process on it (kept current)."""
        with cls._lock:
            channels = cls._of_session.get(id(session))
            if channels is None:
                channels = cls._of_session[id(session)] = _Channels(session)
            on_key = channels.buses.setdefault(key, [])
            on_key.append(bus)
            return on_key

    @classmethod
    def leave(cls, session: zenoh.Session, key: str, bus: ZenohBus) -> None:
        with cls._lock:
            channels = cls._of_session[id(session)]
            channels.buses[key].remove(bus)
            if not channels.buses[key]:
                del channels.buses[key]
            if not channels.buses:
                del cls._of_session[id(session)]
                channels._subscriber.undeclare()

    def _on_sample(self, sample: zenoh.Sample) -> None:
        buses = self.buses.get(str(sample.key_expr))
        if buses:
            payload = sample.payload.to_bytes()
            for bus in tuple(buses):
                bus._on_payload(payload)


def encode_frame(sender: int, msg: can.Message, sequence: int = 0) -> bytes:
    flags = ((_EXTENDED if msg.is_extended_id else 0) | (_REMOTE if msg.is_remote_frame else 0)
             | (_ERROR if msg.is_error_frame else 0))
    return _HEADER.pack(sender, sequence & 0xFFFFFFFF, msg.arbitration_id, flags,
                        msg.dlc) + bytes(msg.data or b"")


def decode_frame(payload: bytes, channel: str) -> tuple[int, int, can.Message]:
    """(sender, sequence number, frame); raise ValueError for anything that is not a
    well-formed frame."""
    if len(payload) < _HEADER.size:
        raise ValueError(f"{len(payload)} bytes is shorter than a frame header")
    sender, sequence, arbitration_id, flags, dlc = _HEADER.unpack_from(payload)
    data = payload[_HEADER.size:]
    remote = bool(flags & _REMOTE)
    if dlc > 8 or (not remote and len(data) != dlc) or (remote and data):
        raise ValueError(f"DLC {dlc} does not match {len(data)} data bytes")
    limit = 0x1FFFFFFF if flags & _EXTENDED else 0x7FF
    if arbitration_id > limit:
        raise ValueError(f"identifier 0x{arbitration_id:X} out of range")
    return sender, sequence, can.Message(
        timestamp=time.time(), arbitration_id=arbitration_id,
        is_extended_id=bool(flags & _EXTENDED), is_remote_frame=remote,
        is_error_frame=bool(flags & _ERROR), dlc=dlc, data=data, channel=channel, is_rx=True)


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

    def __str__(self) -> str:
        return (f"sent {self.sent}, received {self.received}, lost on the way {self.lost}, "
                f"overrun {self.overrun}, malformed {self.malformed}")


class ZenohBus(can.BusABC):
    """python-can bus over Zenoh pub/sub on key ``hil/can/<channel>``.

    Options: ``listen`` / ``connect`` (lists of Zenoh endpoints),
    ``zenoh_config`` (path of a Zenoh config file), ``receive_own_messages``.
    """

    def __init__(self, channel: str, listen=(), connect=(), zenoh_config=None,
                 receive_own_messages: bool = False, **kwargs):
        self.channel_info = f"Zenoh {KEY_PREFIX}{channel}"
        self._channel = str(channel)
        self._receive_own = receive_own_messages
        self._sender = random.getrandbits(63) ^ os.getpid()
        self._sender_bytes = _SENDER.pack(self._sender)
        self._sequence = 0
        self._heard: dict[int, int] = {}      # sender -> its last sequence number seen
        self.counters = FrameCounters()
        self._count_lock = threading.Lock()   # Zenoh delivers from a thread per link
        self._queue: queue.Queue[can.Message] = queue.Queue(RECEIVE_FIFO)
        self._direct: DirectDelivery | None = None
        self._send_lock = threading.Lock()
        settings = ZenohSettings(tuple(listen), tuple(connect),
                                 Path(zenoh_config) if zenoh_config else None)
        self._session = session(settings)
        key = KEY_PREFIX + self._channel
        # not express: Zenoh batches what a burst puts before its TX task sends it. Measured on
        # loopback (8 frames answered by 12, as a cycle of the ur3): round trip p50 340 us
        # against 860 us express, 4 us a put against 30-40 us; a lone frame's round trip is
        # the same either way (300-375 us), Zenoh's batch time limit does not hold it back.
        # DROP: a put never blocks; REMOTE: see the module doc
        self._publisher = self._session.declare_publisher(
            key, congestion_control=zenoh.CongestionControl.DROP, express=False,
            allowed_destination=zenoh.Locality.REMOTE)
        self._key = key
        self._neighbours = _Channels.join(self._session, key, self)
        super().__init__(channel=channel, **kwargs)

    def _on_payload(self, payload: bytes) -> None:
        try:
            sender, sequence, msg = decode_frame(payload, self._channel)
        except ValueError as exc:
            with self._count_lock:
                self.counters.malformed += 1
                malformed = self.counters.malformed
            if malformed % LOG_EVERY == 1:
                log.warning("%s: dropped %d malformed frame(s) from Zenoh: %s",
                            self.channel_info, malformed, exc)
            return
        self._take(sender, sequence, msg)

    def _take(self, sender: int, sequence: int, msg: can.Message) -> None:
        """A frame for this bus: counted, then to the listeners or the receive FIFO."""
        self._count_arrival(sender, sequence)
        direct = self._direct
        if direct is not None:
            direct.deliver(msg)
            return
        try:
            self._queue.put_nowait(msg)
        except queue.Full:
            with self._count_lock:
                self.counters.overrun += 1

    def _count_arrival(self, sender: int, sequence: int) -> None:
        counters = self.counters
        with self._count_lock:
            counters.received += 1
            last = self._heard.get(sender)
            if last is not None:
                # frames that never came: the gap since the sender's previous one (a late
                # one of an earlier sequence, which Zenoh does not produce, counts nothing)
                gap = (sequence - last - 1) & 0xFFFFFFFF
                if gap < 0x80000000:
                    counters.lost += gap
            self._heard[sender] = sequence

    def deliver_to(self, listeners: Iterable[can.Listener],
                   accept: Callable[[can.Message], can.Message | None] | None = None
                   ) -> DirectDelivery:
        """From now on give this bus' received frames to ``listeners`` in Zenoh's callback
        thread (after ``accept``, which may change a frame or return None to drop it), in
        the order they arrive: no queue, and no Notifier thread woken for every frame."""
        self._direct = DirectDelivery(listeners, accept, self._stop_delivery)
        return self._direct

    def _stop_delivery(self, delivery: DirectDelivery) -> None:
        if self._direct is delivery:
            self._direct = None

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        with self._send_lock:
            if self._is_shutdown:
                raise can.CanOperationError(f"{self.channel_info}: the bus is shut down")
            self._sequence += 1
            self.counters.sent += 1
            sequence = self._sequence
            self._publisher.put(encode_frame(self._sender, msg, sequence))
        for neighbour in tuple(self._neighbours):    # buses of this process on this channel
            if neighbour is not self or self._receive_own:
                neighbour._take(self._sender, sequence, received_copy(
                    msg, time.time(), self._channel, neighbour is not self))

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        try:
            return self._queue.get(timeout=timeout), False
        except queue.Empty:
            return None, False

    def shutdown(self) -> None:
        if self._is_shutdown:
            return
        super().shutdown()        # stops the periodic tasks; later sends are refused
        # not under the send lock: a delivery in progress may still be answering
        _Channels.leave(self._session, self._key, self)
        # a put still running in another thread ends first: zenoh refuses to undeclare a
        # publisher in use ("Already borrowed")
        with self._send_lock:
            self._publisher.undeclare()
