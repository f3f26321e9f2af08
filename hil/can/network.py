"""canopen networks as hil's drives and master use them: one frame dispatcher per bus.

python canopen's ``Network`` is a frame dispatcher by arbitration id (``subscribe``) over a
python-can bus, whatever the protocol; hil uses it for every protocol, on both sides of a
bus. What is here replaces the parts of it that cost a cycle too much (measured, see each).
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable, Sequence

import can
import canopen

from hil.can.capabilities import capabilities
from hil.can.delivery import FrameListener
from hil.can.messages import ID_BITS, FrameParts, data_frame, frame_key, sent_key

log = logging.getLogger(__name__)


class NetworkListener(FrameListener):
    """A canopen network's frames in, in one call per frame: what canopen's own
    MessageListener and ``network.notify`` do (every data frame to the network's subscribers
    of its id; a failing subscriber logged, never raised into the bus), plus remote (RTR)
    frames routed by id, which canopen drops.

    A subscriber that fails on a frame (canopen's unpack a frame of the wrong length and
    raise) is counted in :attr:`refused` and logged in one line with the frame, the first
    time per id and then every LOG_EVERY: garbage on a bus is an event to report, not a
    traceback (the traceback is logged at DEBUG level).

    It calls the subscribers itself: ``notify`` would also feed canopen's NodeScanner (node
    discovery, which hil does not use) on every frame; skipping it and ``notify`` took 4 % off
    the ur3's lock-step cycle. Its :attr:`routes` are the network's subscribers: a delivery
    whose one listener it is calls them itself (:class:`~hil.can.delivery.DirectDelivery`),
    failures coming back to :meth:`refuse`.
    :func:`start_network` puts one in place of canopen's, as ``network.frame_listener``.
    """

    LOG_EVERY = 1000

    def __init__(self, network: canopen.Network):
        self.subscribers = self.routes = network.subscribers
        #: RTR id -> handler (called with the id)
        self.remote_handlers: dict[int, Callable[[int], None]] = {}
        #: frames a subscriber could not take
        self.refused = 0
        self._refused_by_id: dict[int, int] = {}

    def on_message_received(self, msg: can.Message) -> None:
        if msg.is_remote_frame:
            handler = self.remote_handlers.get(msg.arbitration_id)
            if handler is not None:
                handler(msg.arbitration_id)
        elif not msg.is_error_frame:
            self.on_frame(frame_key(msg), msg.data, msg.timestamp)

    def on_frame(self, key: int, data: bytearray, timestamp: float) -> None:
        for callback in self.subscribers.get(key, ()):
            try:
                callback(key, data, timestamp)
            except Exception as exc:
                self.refuse(key, data, callback, exc)

    def refuse(self, key: int, data: bytearray, callback, exc: Exception) -> None:
        can_id = key & ID_BITS
        self.refused += 1
        count = self._refused_by_id.get(can_id, 0) + 1
        self._refused_by_id[can_id] = count
        if count % self.LOG_EVERY == 1:
            log.warning("frame 0x%03X [%s] refused by %s: %s: %s (%d from this id so far)",
                        can_id, bytes(data).hex(" "),
                        # a function's name where it has one, for the log only
                        getattr(callback, "__qualname__", callback), type(exc).__name__, exc,
                        count)
        log.debug("frame 0x%03X refused", can_id, exc_info=exc)


class CanopenNetwork(canopen.Network):
    """canopen's Network, its frames built by :func:`hil.can.messages.data_frame`: the
    same ``can.Message`` in 60 % of the time (a ur3 cycle sends 20 frames); or, on a bus
    that sends frames from their parts (``frame_sender``), no message at all, and a
    cycle's frames in one call (:meth:`send_frames`)."""

    #: the bus' frame sender (BusCapabilities.frame_sender), set by :func:`start_network`
    frame_sender: Callable[[Sequence[FrameParts]], None] | None = None

    def send_message(self, can_id: int, data: bytes, remote: bool = False) -> None:
        # canopen's own send_message but for how the frame is built (canopen 2.4), and its
        # check() called only where the notifier has an error to raise (never, delivered
        # directly: one call less a frame)
        if self.frame_sender is not None and not remote:
            self.send_frames(((can_id, data),))
            return
        if not self.bus:
            raise RuntimeError("Not connected to CAN bus")
        with self.send_lock:
            self.bus.send(data_frame(can_id, data, remote))
        if self.notifier is not None and self.notifier.exception is not None:
            self.check()

    def send_frames(self, frames: Sequence[tuple[int, bytes]]) -> None:
        """Data frames (arbitration id, data), in order, as :meth:`send_message` sends each;
        in one call to the bus where it sends frames from their parts."""
        send_frames = self.frame_sender
        if send_frames is None:
            for can_id, data in frames:
                self.send_message(can_id, data)
            return
        if not self.bus:
            raise RuntimeError("Not connected to CAN bus")
        with self.send_lock:    # sent_key's standard-id case inline: one call less a frame
            send_frames([(can_id if can_id <= 0x7FF else sent_key(can_id), data)
                         for can_id, data in frames])
        if self.notifier is not None and self.notifier.exception is not None:
            self.check()

    def send_in_order(self, frames: Iterable[tuple[int, bytes, bool]]) -> None:
        """Frames (arbitration id, data, remote) in order: each run of data frames in one
        :meth:`send_frames`, a remote frame (ODrive's requests) on its own."""
        run: list[tuple[int, bytes]] = []
        for can_id, data, remote in frames:
            if not remote:
                run.append((can_id, data))
                continue
            if run:
                self.send_frames(run)
                run = []
            self.send_message(can_id, data, True)
        if run:
            self.send_frames(run)


def start_network(bus: can.BusABC, timeout: float = 0.1,
                  network_class: type[CanopenNetwork] = CanopenNetwork) -> CanopenNetwork:
    """A canopen network (of ``network_class``) on ``bus`` with its frames flowing and RTR
    frames routed: handed over in the thread that brings them where the bus can
    (``deliver_to``: hil-virtual, zenoh; see hil.can.delivery), else by a python-can
    Notifier (``network.notifier`` either way); sent from their parts where the bus can
    (``frame_sender``: hil-virtual, zenoh)."""
    network = network_class(bus)
    network.frame_listener = NetworkListener(network)
    network.listeners = [network.frame_listener]     # canopen's MessageListener replaced
    direct = capabilities(bus).deliver_to(network.listeners)
    network.notifier = direct or can.Notifier(bus, network.listeners, timeout)
    network.frame_sender = capabilities(bus).frame_sender()
    return network
