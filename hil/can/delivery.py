"""Frames handed to a bus' listeners in the thread that brings them, without a Notifier.

python-can's :class:`can.Notifier` reads a bus from a thread of its own: every frame
crosses a queue and wakes that thread, a thread switch under the GIL per frame or burst.
A bus that already runs code when a frame arrives (``hil-virtual`` in the sender's thread,
``zenoh`` in Zenoh's callback thread) can call the listeners there instead:
``bus.deliver_to(listeners)`` returns a :class:`DirectDelivery`, which stands where the
Notifier would (``stop``, ``add_listener``, ``exception``).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Iterable

import can

log = logging.getLogger(__name__)


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

    def add_listener(self, listener: can.Listener) -> None:
        with self._lock:
            self.listeners.append(listener)
            self._receivers.append(_receiver(listener))

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
