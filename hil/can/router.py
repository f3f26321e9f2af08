"""hil's frame router: one per bus and side, what every protocol's drives and axes talk through.

A protocol subscribes a handler by identifier (and mask), and sends :class:`Frame` values; the
router takes a bus' frames of one delivery together (a cycle's, where the bus brings them at
once: ``hil-virtual``, ``zenoh``) and calls the handlers of each. It stands where python
canopen's ``Network`` stood for every family: canopen itself stays behind
:mod:`hil.protocols.cia402`, which puts its own network on a router (CANopen's services are
canopen's; the bus is hil's).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

import can

from hil.can.capabilities import capabilities
from hil.can.delivery import FrameListener
from hil.can.frame import Frame
from hil.can.messages import frame_of, message_of
from hil.can.routes import Handler, Routes

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Subscription:
    """Frames a drive or an axis listens to, with their handler: the arguments of one
    :meth:`FrameRouter.subscribe`."""

    identifier: int
    handler: Handler
    extended: bool = False
    remote: bool = False
    #: the identifier bits that must match (None: all of them)
    mask: int | None = None

    def join(self, router: FrameRouter) -> None:
        router.subscribe(self.identifier, self.handler, self.extended, self.remote, self.mask)

    def leave(self, router: FrameRouter) -> None:
        router.unsubscribe(self.identifier, self.handler, self.extended, self.remote,
                           self.mask)


class FrameRouter(FrameListener):
    """Frames of one bus to their subscribers; frames to the bus.

    A subscriber that raises on a frame (a frame of the wrong length a codec refuses) is
    counted in :attr:`refused` and logged in one line with the frame, the first time per
    identifier and then every LOG_EVERY: garbage on a bus is an event to report, not a
    traceback (the traceback is logged at DEBUG level); the other subscribers still get it.

    ``keep_sending``: a frame the bus refuses (its transmit queue full, the bus gone) is
    lost and counted in :attr:`lost_frames`, as a drive's CAN controller loses it, and the
    sender runs on (the drives' side: a send error must not stop the plant mid-step);
    otherwise the error is raised to the sender (a master must know).

    ``classical``: the name of the bus where it is a classical CAN bus. An FD frame on it
    reaches no subscriber: a classical CAN controller destroys it with an error frame
    (:class:`hil.protocols.base.CanFd`), so no device acts on it. It is counted in
    :attr:`fd_on_classical` and logged, the first time per identifier and every LOG_EVERY,
    naming the bus and what ``describe`` says of the frame (the node it is for).
    """

    LOG_EVERY = 1000

    def __init__(self, bus: can.BusABC, keep_sending: bool = False,
                 classical: str | None = None,
                 describe: Callable[[Frame], str | None] | None = None):
        self.bus = bus
        self.keep_sending = keep_sending
        self.classical = classical
        self._describe = describe
        #: frames a subscriber could not take; frames the bus would not send (keep_sending)
        self.refused = 0
        self.lost_frames = 0
        #: FD frames that arrived on a classical bus
        self.fd_on_classical = 0
        #: the subscribers, and the loop that hands them a delivery's frames (compiled)
        self._routes = Routes(self._refuse, None if classical is None else self._fd_on_classical)
        self._refused_by_id: dict[int, int] = {}
        self._send_lock = threading.Lock()
        self._frame_sender = capabilities(bus).frame_sender()
        self._delivery = None

    # --- subscribing ------------------------------------------------------------------

    def subscribe(self, identifier: int, handler: Handler, extended: bool = False,
                  remote: bool = False, mask: int | None = None) -> None:
        """Call ``handler`` with every data frame of ``identifier`` (a remote frame's with
        ``remote``), or with ``mask``, of every identifier whose masked bits equal it."""
        self._routes.subscribe(identifier, handler, extended, remote, mask)

    def unsubscribe(self, identifier: int, handler: Handler, extended: bool = False,
                    remote: bool = False, mask: int | None = None) -> None:
        """Undo one :meth:`subscribe` of these arguments (none: nothing happens)."""
        self._routes.unsubscribe(identifier, handler, extended, remote, mask)

    def handlers(self, identifier: int, extended: bool = False, remote: bool = False
                 ) -> tuple[Handler, ...]:
        """The subscribers of ``identifier`` by identifier (not by mask)."""
        return self._routes.by_identifier(identifier, extended, remote)

    def has_subscribers(self) -> bool:
        """Whether any handler is subscribed, by identifier or by mask."""
        return self._routes.any()

    # --- receiving --------------------------------------------------------------------

    def on_frames(self, frames: Iterable[Frame]) -> None:
        self._routes.dispatch(frames)

    def on_message_received(self, msg: can.Message) -> None:
        self._routes.dispatch((frame_of(msg),))

    def _refuse(self, frame: Frame, handler: Handler, exc: Exception) -> None:
        self.refused += 1
        count = self._refused_by_id.get(frame.identifier, 0) + 1
        self._refused_by_id[frame.identifier] = count
        if count % self.LOG_EVERY == 1:
            log.warning("frame %s refused by %s: %s: %s (%d from this id so far)", frame,
                        # a function's name where it has one, for the log only
                        getattr(handler, "__qualname__", handler), type(exc).__name__, exc,
                        count)
        log.debug("frame %s refused", frame, exc_info=exc)

    def _fd_on_classical(self, frame: Frame) -> None:
        self.fd_on_classical += 1
        count = self._refused_by_id.get(frame.identifier, 0) + 1
        self._refused_by_id[frame.identifier] = count
        if count % self.LOG_EVERY == 1:
            what = self._describe(frame) if self._describe is not None else None
            log.warning("bus '%s': CAN FD frame %s%s on this classical bus: dropped, as a "
                        "classical CAN controller destroys it with an error frame (%d so "
                        "far; fd: true on the bus if its devices speak CAN FD)",
                        self.classical, frame, f" ({what})" if what else "",
                        self.fd_on_classical)

    # --- sending ------------------------------------------------------------------------

    def send(self, frame: Frame) -> None:
        """Send one frame."""
        self.send_frames((frame,))

    def send_frames(self, frames: Sequence[Frame]) -> None:
        """Send frames, in order: in one call to the bus where it takes frames as values
        (``hil-virtual``, ``zenoh``), else one ``can.Message`` each."""
        if not frames:
            return
        try:
            with self._send_lock:
                if self._frame_sender is not None:
                    self._frame_sender(frames)
                else:
                    for frame in frames:
                        self.bus.send(message_of(frame))
        except can.CanError as exc:
            if not self.keep_sending:
                raise
            self._lost(frames[0], len(frames), exc)

    def _lost(self, frame: Frame, count: int, exc: can.CanError) -> None:
        before, self.lost_frames = self.lost_frames, self.lost_frames + count
        # the first, the 1001st, ...: whichever of them this loss counted
        if (before - 1) // self.LOG_EVERY != (self.lost_frames - 1) // self.LOG_EVERY:
            log.warning("frame %s was lost (%d so far): %s", frame, self.lost_frames, exc)

    # --- life ---------------------------------------------------------------------------

    def stop(self, timeout: float = 1.0) -> None:
        """Stop taking frames from the bus (the bus stays open: its owner closes it): no
        handler is called from now on, not even for the rest of a delivery in progress
        (its routes are emptied in place, where that delivery reads them)."""
        self._routes.clear()
        # a python-can Notifier stops its listeners too (this again): taken first
        delivery, self._delivery = self._delivery, None
        if delivery is not None:
            delivery.stop(timeout)


def start_router(bus: can.BusABC, keep_sending: bool = False, timeout: float = 0.1,
                 classical: str | None = None,
                 describe: Callable[[Frame], str | None] | None = None) -> FrameRouter:
    """A router on ``bus`` with its frames flowing: handed over in the thread that brings
    them where the bus can (``deliver_to``: hil-virtual, zenoh; see hil.can.delivery), else
    read by a python-can Notifier (``timeout``: its read's). ``classical`` and ``describe``:
    see :class:`FrameRouter`."""
    router = FrameRouter(bus, keep_sending, classical, describe)
    router._delivery = (capabilities(bus).deliver_to([router])
                        or can.Notifier(bus, [router], timeout))
    return router
