"""A Zenoh session's CAN channels (the fan-out under :class:`hil.can.zenoh_bus.ZenohBus`):
one subscriber per session for every channel, feeding the process' buses on each, and the
frames a thread sends held for one message.

The bus builds on its channels (it joins and leaves them); the channels know a bus only as
a :class:`ChannelBus`, what they call of it, so that they need not import the bus back."""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence
from contextlib import AbstractContextManager, nullcontext
from typing import Protocol

import can
import zenoh

from hil.can.frame import Frame
from hil.can.zenoh_links import ChannelLinks, seen_by_others
from hil.can.zenoh_receipts import declare_receipts
from hil.can.zenoh_wire import KEY_PREFIX, Message, decode_frames
from hil.zenoh_session import ZenohSettings


class ChannelBus(Protocol):
    """A bus on a session's channels, as the channels use it: the parts of its send and
    receive that the session's one subscriber and one send lock serve
    (:class:`hil.can.zenoh_bus.ZenohBus` is one)."""

    channel_info: str
    monitors: bool                 # a log's bus: it answers the session's receipt queries
    _channel: str
    _settings: ZenohSettings
    _publisher: zenoh.Publisher
    _is_shutdown: bool

    def heard(self) -> dict[int, int]: ...

    def _count_malformed(self, problem: ValueError) -> None: ...

    def _on_message(self, message: Message, arrived: float, now: float) -> None: ...

    def _section(self, frames: Sequence[Frame], sent_at: float, now: float
                 ) -> tuple[int, bytes]: ...

    def _to_neighbours(self, first: int, frames: Sequence[Frame]) -> None: ...


class Outbox(threading.local):
    """A thread's frames held for one message, per bus in the order the buses first sent,
    and how deep its holds nest."""

    depth = 0

    def __init__(self):
        self.held: dict[ChannelBus, list[Frame]] = {}


class Hold(AbstractContextManager):
    """A block whose sends on a session's buses go out in one message at its end (nested: at
    the outermost's); one per session, reused: its state is each thread's :class:`Outbox`.
    (A ``contextmanager`` generator made and stepped each cycle cost the controller more a
    cycle, docs/performance.md, "2026-12-02: where a lock-step cycle across processes goes".)"""

    def __init__(self, channels: Channels):
        self._channels = channels

    def __enter__(self) -> None:
        self._channels.hold()

    def __exit__(self, *exc_info) -> None:
        self._channels.release()


class Channels:
    """A session's CAN channels: the buses of this process on each key, fed by the one
    subscriber of the session (and by each other), and what their threads send: held for
    one message (:class:`Outbox`) and put under one lock, so that every sender's messages
    keep the order of their sequence numbers."""

    _of_session: dict[int, Channels] = {}
    _lock = threading.Lock()

    def __init__(self, session: zenoh.Session):
        self.buses: dict[str, list[ChannelBus]] = {}
        #: per key with buses: who else is on its channel, linked or not (hil.can.zenoh_links)
        self.links: dict[str, ChannelLinks] = {}
        self.outbox = Outbox()
        self.send_lock = threading.Lock()
        #: the block whose sends go out together (every bus of the session hands out this one)
        self.together = Hold(self)
        #: entered around each message's delivery (None: nothing): see ZenohBus.deliver_under
        self.guard: AbstractContextManager | None = None
        self._subscriber = session.declare_subscriber(
            KEY_PREFIX + "**", self._on_sample, allowed_origin=zenoh.Locality.REMOTE)
        self._receipts = None        # the queryable, once a monitor joins (hil.can.zenoh_receipts)

    @classmethod
    def join(cls, session: zenoh.Session, key: str, bus: ChannelBus
             ) -> tuple[Channels, list[ChannelBus]]:
        """Add ``bus`` on ``key``; returns the session's channels and the buses of this
        process on ``key`` (kept current)."""
        with cls._lock:
            channels = cls._of_session.get(id(session))
            if channels is None:
                channels = cls._of_session[id(session)] = Channels(session)
            on_key = channels.buses.setdefault(key, [])
            on_key.append(bus)
            if key not in channels.links:
                channels.links[key] = ChannelLinks(session, key.removeprefix(KEY_PREFIX),
                                                   seen_by_others(bus._settings))
            if bus.monitors and channels._receipts is None:
                channels._receipts = declare_receipts(session, channels._heard)
            return channels, on_key

    @classmethod
    def leave(cls, session: zenoh.Session, key: str, bus: ChannelBus) -> None:
        with cls._lock:
            channels = cls._of_session[id(session)]
            channels.buses[key].remove(bus)
            links = None
            if not channels.buses[key]:
                del channels.buses[key]
                links = channels.links.pop(key)
            last = not channels.buses
            if last:
                del cls._of_session[id(session)]
        if links is not None:   # outside the lock, as below
            links.close()
        if last:          # outside the lock: Zenoh may wait for a callback under way
            channels._subscriber.undeclare()
            if channels._receipts is not None:
                channels._receipts.undeclare()

    def _heard(self) -> list[tuple[str, dict[int, int]]]:
        """Each monitor bus' channel and the last frame it heard of each sender (in a
        Zenoh thread, as _on_sample: copies, no lock a shutdown may hold)."""
        monitors = [bus for on_key in tuple(self.buses.values()) for bus in tuple(on_key)
                    if bus.monitors]
        return [(bus._channel, bus.heard()) for bus in monitors]

    def hold(self) -> None:
        """What this thread sends on the session's buses from now on waits for
        :meth:`release` (nested: the outermost)."""
        self.outbox.depth += 1

    def release(self) -> None:
        outbox = self.outbox
        outbox.depth -= 1
        if outbox.depth == 0 and outbox.held:
            held, outbox.held = outbox.held, {}
            self.put(held)

    def put(self, held: dict[ChannelBus, list[Frame]]) -> None:
        """One message of each bus' ``held`` frames (a section each, in the
        order the buses first sent), on the first bus' key; copies to this process' buses on
        each channel. Buses shut down meanwhile send nothing and raise CanOperationError,
        after the rest went out."""
        firsts = []
        with self.send_lock:
            live = [(bus, frames) for bus, frames in held.items() if not bus._is_shutdown]
            if live:
                sent_at, now = time.time(), time.monotonic()
                sections = []
                for bus, frames in live:
                    first, section = bus._section(frames, sent_at, now)
                    firsts.append(first)
                    sections.append(section)
                live[0][0]._publisher.put(b"".join(sections))
        for (bus, frames), first in zip(live, firsts):
            bus._to_neighbours(first, frames)
        if len(live) < len(held):
            shut = ", ".join(bus.channel_info for bus in held if bus._is_shutdown)
            raise can.CanOperationError(f"{shut}: the bus is shut down")

    def _on_sample(self, sample: zenoh.Sample) -> None:
        payload = sample.payload.to_bytes()
        arrived = time.time()
        try:
            messages = decode_frames(payload)
        except ValueError as exc:
            for bus in tuple(self.buses.get(str(sample.key_expr), ())):
                bus._count_malformed(exc)
            return
        now = time.monotonic()
        # what the listeners send in answer goes out together, in one message, once the
        # guard is left (the put never holds it)
        self.hold()
        try:
            with self.guard or nullcontext():
                for message in messages:
                    buses = self.buses.get(KEY_PREFIX + message.channel)
                    for bus in tuple(buses or ()):     # each receiver copies what it keeps
                        bus._on_message(message, arrived, now)
        finally:
            self.release()
