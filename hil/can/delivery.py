"""Frames handed to a bus' listeners in the thread that brings them, without a Notifier.

python-can's :class:`can.Notifier` reads a bus from a thread of its own: every frame
crosses a queue and wakes that thread, a thread switch under the GIL per frame or burst.
A bus that already runs code when a frame arrives (``hil-virtual`` in the sender's thread,
``zenoh`` in Zenoh's callback thread) can call the listeners there instead:
``bus.deliver_to(listeners)`` returns a :class:`DirectDelivery`, which stands where the
Notifier would (``stop``, ``add_listener``, ``exception``).

Where every listener is a :class:`FrameListener` (hil's canopen networks) and nothing
rewrites the frames on the way in (no ``accept``), the delivery also takes a data frame as
its parts, a sender's frames in one call (:meth:`DirectDelivery.deliver_frames`): a bus
that sends from parts (hil's own networks on ``hil-virtual`` and ``zenoh``) then builds no
``can.Message`` for them at all. hil's cycle exchanges 20 frames (ur3) between hil's own
ends; a message built and copied per frame was measured as a large share of a lock-step
cycle (docs/performance.md). Where the only listener has :attr:`FrameListener.routes` (its
callbacks by dispatch key: a canopen network's subscribers), the delivery calls them itself,
one Python call less a frame.
"""

from __future__ import annotations

import logging
import threading
from abc import abstractmethod
from collections.abc import Callable, Iterable

import can

from hil.can.messages import FrameParts, identifier, received_frame

log = logging.getLogger(__name__)


class FrameListener(can.Listener):
    """A listener that also takes a data frame as its parts: its dispatch key
    (:func:`hil.can.messages.frame_key`), its own data and its receive timestamp, in
    place of a ``can.Message`` (never remote or error frames: those come as messages)."""

    #: where this listener's frames go, by dispatch key (read live, at every frame): a
    #: delivery whose one listener this is calls them itself, one Python call less a frame
    #: than :meth:`on_frame` (docs/performance.md, 2026-12-01); None: through on_frame
    routes: dict[int, list[Callable[[int, bytearray, float], None]]] | None = None

    @abstractmethod
    def on_frame(self, key: int, data: bytearray, timestamp: float) -> None:
        """One data frame, by its parts (to its :attr:`routes`, where it has them)."""

    def refuse(self, key: int, data: bytearray,
               callback: Callable[[int, bytearray, float], None], exc: Exception) -> None:
        """A route's callback raised on a frame (its routes called by a delivery): by
        default logged, as a failing listener is."""
        log.exception("listener %r failed on frame 0x%X", callback, key, exc_info=exc)


class DirectDelivery:
    """A bus' listeners, called in the thread that brings each frame; what a
    ``can.Notifier`` is to a queued bus (``stop``, ``add_listener``), without its thread.

    One frame at a time, as a Notifier thread would have it; the lock is re-entrant so that
    a listener may send frames that come back to this bus. A listener that raises is logged
    and the others still get the frame. ``on_stop`` is the bus' own: from then on it queues
    its frames for ``recv`` again. Once :meth:`stop` returns no listener runs any more, as
    once a Notifier's thread is joined.
    """

    #: as ``can.Notifier.exception`` (canopen checks it after each send): listener errors
    #: are logged here, never kept
    exception: Exception | None = None

    def __init__(self, listeners: Iterable[can.Listener],
                 accept: Callable[[can.Message], can.Message | None] | None,
                 on_stop: Callable[[DirectDelivery], None]):
        self.listeners = list(listeners)
        # each listener's own method, called straight (can.Listener.__call__ is one more
        # Python call per frame and listener; plain callables are listeners too)
        self._receivers = [_receiver(listener) for listener in self.listeners]
        #: whether :meth:`deliver_frames` takes frames as parts (read by senders unlocked: a
        #: frame that meets a change of it is still delivered, as a message if need be)
        self.takes_frames = accept is None and all(
            isinstance(listener, FrameListener) for listener in self.listeners)
        self._frame_receivers = ([listener.on_frame for listener in self.listeners]
                                 if self.takes_frames else [])
        self._routed = self._one_routed_listener()
        self._accept = accept
        self._on_stop = on_stop
        self._lock = threading.RLock()
        self._stopped = False

    def deliver(self, msg: can.Message) -> None:
        if self._accept is not None:
            msg = self._accept(msg)
            if msg is None:
                return
        with self._lock:
            if self._stopped:           # it came in while stop() waited for the lock
                return
            for receive in self._receivers:
                try:
                    receive(msg)
                except Exception:          # as python-can's Notifier: one bad listener
                    log.exception("listener %r failed on %s", receive, msg)

    def deliver_frames(self, frames: Iterable[FrameParts], timestamp: float) -> None:
        """Data frames by their parts, in order, in one hold of the lock: each listener gets
        its own copy of each frame's data."""
        with self._lock:
            listener = self._routed
            if listener is not None:
                self._route(listener, frames, timestamp)
                return
            for key, data in frames:
                if self._stopped:           # a listener stopped it
                    return
                if not self.takes_frames:   # a listener that wants messages came meanwhile
                    self.deliver(received_frame(timestamp, *identifier(key), False, False,
                                                len(data), data, None))
                    continue
                for receive in self._frame_receivers:
                    try:
                        receive(key, bytearray(data), timestamp)
                    except Exception:          # as deliver
                        log.exception("listener %r failed on frame 0x%X", receive, key)

    def _route(self, listener: FrameListener, frames: Iterable[FrameParts],
               timestamp: float) -> None:
        """deliver_frames for one listener with routes (lock held): its callbacks of each
        frame's key called here, as its on_frame would call them."""
        routes = listener.routes
        for key, data in frames:
            if self._stopped:           # a listener stopped it
                return
            if self._routed is not listener:    # a listener came meanwhile
                self.deliver_frames(((key, data),), timestamp)
                continue
            callbacks = routes.get(key)
            if callbacks:
                data = bytearray(data)
                for callback in callbacks:
                    try:
                        callback(key, data, timestamp)
                    except Exception as exc:
                        listener.refuse(key, data, callback, exc)

    def add_listener(self, listener: can.Listener) -> None:
        with self._lock:
            self.listeners.append(listener)
            self._receivers.append(_receiver(listener))
            if isinstance(listener, FrameListener):
                self._frame_receivers.append(listener.on_frame)
            else:
                self.takes_frames = False
            self._routed = self._one_routed_listener()

    def _one_routed_listener(self) -> FrameListener | None:
        # the delivery calls the routes itself only where they are all there is to call
        if self.takes_frames and len(self.listeners) == 1:
            listener = self.listeners[0]
            if listener.routes is not None:
                return listener
        return None

    def stop(self, timeout: float = 5.0) -> None:
        """Stop delivering (the bus queues its frames again), after a delivery in progress
        in another thread; ``timeout`` (s) as for a Notifier: how long to wait for it."""
        self._on_stop(self)
        acquired = self._lock.acquire(timeout=timeout)
        self._stopped = True
        if acquired:
            self._lock.release()


def _receiver(listener: can.Listener | Callable[[can.Message], None]
              ) -> Callable[[can.Message], None]:
    # a Listener or a plain callable, as python-can's Notifier takes either
    return getattr(listener, "on_message_received", listener)
