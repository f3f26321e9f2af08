"""Frames handed to a bus' listeners in the thread that brings them, without a Notifier.

python-can's :class:`can.Notifier` reads a bus from a thread of its own: every frame
crosses a queue and wakes that thread, a thread switch under the GIL per frame or burst.
A bus that already runs code when a frame arrives (``hil-virtual`` in the sender's thread,
``zenoh`` in Zenoh's callback thread) can call the listeners there instead:
``bus.deliver_to(listeners)`` returns a :class:`DirectDelivery`, which stands where the
Notifier would (``stop``, ``add_listener``, ``exception``).

Where every listener is a :class:`FrameListener` (hil's frame routers) and nothing rewrites
the frames on the way in (no ``accept``), the delivery also takes frames as
:class:`~hil.can.frame.Frame` values, a sender's frames in one call
(:meth:`DirectDelivery.deliver_frames`): a bus that sends frames as values (hil's routers on
``hil-virtual`` and ``zenoh``) then builds no ``can.Message`` for them at all. hil's cycle
exchanges 20 frames (ur3) between hil's own ends; a message built and copied per frame was
measured as a large share of a lock-step cycle (docs/performance.md,
"2026-11-28, third step: frames between hil's own ends as their parts (issue 48)").
"""

from __future__ import annotations

import logging
import threading
from abc import abstractmethod
from collections.abc import Callable, Iterable, Sequence

import can

from hil.can.frame import Frame
from hil.can.messages import message_of

log = logging.getLogger(__name__)


class FrameListener(can.Listener):
    """A listener that also takes frames as :class:`~hil.can.frame.Frame` values, a
    delivery's frames in one call, in place of a ``can.Message`` each."""

    @abstractmethod
    def on_frames(self, frames: Sequence[Frame]) -> None:
        """Frames of one delivery, in order."""


class DirectDelivery:
    """A bus' listeners, called in the thread that brings each frame; what a
    ``can.Notifier`` is to a queued bus (``stop``, ``add_listener``), without its thread.

    One delivery at a time, as a Notifier thread would have it; the lock is re-entrant so that
    a listener may send frames that come back to this bus. A listener that raises is logged
    and the others still get the frame. ``on_stop`` is the bus' own: from then on it queues
    its frames for ``recv`` again. Once :meth:`stop` returns no listener runs any more, as
    once a Notifier's thread is joined.
    """

    def __init__(self, listeners: Iterable[can.Listener],
                 accept: Callable[[can.Message], can.Message | None] | None,
                 on_stop: Callable[[DirectDelivery], None]):
        self.listeners = list(listeners)
        # each listener's own method, called straight (can.Listener.__call__ is one more
        # Python call per frame and listener; plain callables are listeners too)
        self._receivers = [_receiver(listener) for listener in self.listeners]
        #: whether every listener takes frames as values (read by senders unlocked: a frame
        #: that meets a change of it is still delivered, as a message if need be)
        self.takes_frames = accept is None and all(
            isinstance(listener, FrameListener) for listener in self.listeners)
        self._frame_receivers = ([listener.on_frames for listener in self.listeners]
                                 if self.takes_frames else [])
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

    def deliver_frames(self, frames: Sequence[Frame], channel=None) -> None:
        """Frames, in order, in one hold of the lock (as messages on ``channel`` where a
        listener wants messages)."""
        with self._lock:
            if self._stopped:
                return
            if not self.takes_frames:   # a listener that wants messages
                for frame in frames:
                    self.deliver(message_of(frame, channel, True))
                return
            for receive in self._frame_receivers:
                try:
                    receive(frames)
                except Exception:          # as deliver
                    log.exception("listener %r failed on %d frame(s)", receive, len(frames))

    def add_listener(self, listener: can.Listener) -> None:
        with self._lock:
            self.listeners.append(listener)
            self._receivers.append(_receiver(listener))
            if isinstance(listener, FrameListener):
                self._frame_receivers.append(listener.on_frames)
            else:
                self.takes_frames = False

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
