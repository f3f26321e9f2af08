"""python-can's in-process ``virtual`` bus, made cheap enough for a control loop.

Three differences from python-can's :class:`~can.interfaces.virtual.VirtualBus`, each
measured in ``hil bench`` (docs/performance.md,
"How the cycle got here (measured at the time, on earlier commits)"):

* ``send`` builds each receiver's copy of a frame field by field
  (:func:`hil.can.messages.received_copy`); python-can's goes through ``copy.deepcopy``,
  which took a large share of the controller's time per cycle;
* :meth:`VirtualBus.deliver_to` hands a receiver's frames to its listeners in the
  sending thread (:mod:`hil.can.delivery`), where a Notifier thread would take them from
  a queue: a lock-step cycle becomes one chain of calls instead of a thread switch per
  burst of frames;
* between hil's own ends (a frame router of :mod:`hil.can.router` on each) a frame goes
  as its :class:`~hil.can.frame.Frame` value, a cycle's frames of one sender in one call
  (:meth:`VirtualBus.send_frames`, :meth:`~hil.can.delivery.DirectDelivery.deliver_frames`):
  no ``can.Message`` is built for it unless a receiver wants one (python-can's own buses,
  a listener of yours). A frame handed over so keeps the sender's timestamp (0.0: none):
  stamping each would cost a frame's build again, for a time no receiver of hil reads.

Channels are python-can's own, so ``hil-virtual`` and ``virtual`` buses on one channel
hear each other; a bus without direct delivery queues its frames for ``recv`` as usual. A
frame that python-can's own ``virtual`` bus sends to a bus with direct delivery is handed
over in the sender's thread too (:class:`Inbox`): a user's master on ``virtual`` in front of
hil's drives (``hil.testing.DrivesBench``) has its frame taken by the drive when its ``send``
returns, as a lock-step bench needs. ``fd=True`` lets it send and hear CAN FD frames, as
a SocketCAN socket (:mod:`hil.can.fd_option`). Picked by ``interface="hil-virtual"``.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from typing import Any

import can
from can.interfaces import virtual

from hil.can.capabilities import BusCapabilities
from hil.can.delivery import DirectDelivery
from hil.can.fd_option import fd_protocol, refuse_fd_send, takes_fd
from hil.can.frame import Frame
from hil.can.messages import frame_of, message_of, received_copy

#: a receiving bus' queue -> who takes its frames directly (read without a lock in send)
_DIRECT: dict[queue.Queue, DirectDelivery] = {}
_DIRECT_LOCK = threading.Lock()


class Inbox(queue.Queue):
    """A ``hil-virtual`` bus' receive queue: a frame put into it (python-can's own senders
    put every frame into each receiver's queue) goes to the bus' direct delivery where it
    has one, in the sender's thread, else into the queue for ``recv``. Without it a frame of
    a python-can ``virtual`` bus waited in the queue of a bus that delivered directly, read
    by no one (hil's own senders look the delivery up themselves, in :meth:`VirtualBus.send`)."""

    def put(self, item: can.Message, block: bool = True, timeout: float | None = None) -> None:
        direct = _DIRECT.get(self)
        if direct is None:
            super().put(item, block, timeout)
        else:
            direct.deliver(item)


class VirtualBus(virtual.VirtualBus, BusCapabilities):
    """python-can's VirtualBus, sending without ``copy.deepcopy``, with direct delivery."""

    def __init__(self, channel: Any = "channel-0", fd: bool = False, **kwargs):
        protocol = fd_protocol(fd, kwargs)
        super().__init__(channel, protocol=protocol, **kwargs)
        self._fd = takes_fd(protocol)       # hil.can.fd_option
        # python-can's queue, swapped for one that also delivers: a frame a sender put into
        # the old one meanwhile (a bus opened mid-burst) moves over, in order
        inbox = Inbox(self.queue.maxsize)
        with virtual.channels_lock:
            while not self.queue.empty():
                inbox.put_nowait(self.queue.get_nowait())
            self.channel[self.channel.index(self.queue)] = inbox
            self.queue = inbox

    def deliver_to(self, listeners: Iterable[can.Listener],
                   accept: Callable[[can.Message], can.Message | None] | None = None
                   ) -> DirectDelivery:
        """From now on give this bus' received frames to ``listeners`` in the sending
        thread (after ``accept``, which may change a frame or return None to drop it)."""
        delivery = DirectDelivery(listeners, accept, self._stop_delivery)
        with _DIRECT_LOCK:
            _DIRECT[self.queue] = delivery
        return delivery

    def _stop_delivery(self, delivery: DirectDelivery) -> None:
        with _DIRECT_LOCK:
            if _DIRECT.get(self.queue) is delivery:
                del _DIRECT[self.queue]

    def frame_sender(self) -> Callable[[Sequence[Frame]], None]:
        return self.send_frames

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if not self._open:                  # python-can's _check_if_open, one call less
            self._check_if_open()
        if msg.is_fd and not self._fd:
            refuse_fd_send(self.channel_info, msg)
        timestamp = msg.timestamp if self.preserve_timestamps else time.time()
        all_sent = True
        for bus_queue in self.channel:
            if bus_queue is self.queue and not self.receive_own_messages:
                continue
            direct = _DIRECT.get(bus_queue)
            if direct is not None:
                if direct.takes_frames and bus_queue is not self.queue:
                    direct.deliver_frames((frame_of(msg, timestamp),))
                else:
                    direct.deliver(received_copy(msg, timestamp, self.channel_id,
                                                 bus_queue is not self.queue))
                continue
            copy = received_copy(msg, timestamp, self.channel_id, bus_queue is not self.queue)
            try:
                bus_queue.put(copy, block=True, timeout=timeout)
            except queue.Full:
                all_sent = False
        if not all_sent:
            raise can.CanOperationError("Could not send message to one or more recipients")

    def send_frames(self, frames: Sequence[Frame]) -> None:
        """Send frames, in order: handed over as they are where every receiver takes frames
        as values, else each built and sent as :meth:`send`
        sends it. Each frame reaches every receiver before the next frame reaches any, as
        one :meth:`send` after another would; the receivers are the channel's when the call
        begins (a bus opened by a receiver meanwhile hears the frames after it, as a node
        that joins a bus mid-burst does)."""
        if not self._open:
            self._check_if_open()
        directs = []
        for bus_queue in self.channel:
            if bus_queue is not self.queue:
                direct = _DIRECT.get(bus_queue)
                if direct is None or not direct.takes_frames:
                    break
                directs.append(direct)
            elif self.receive_own_messages:
                break
        else:
            if len(directs) == 1:   # one receiver: frame by frame is receiver by receiver
                directs[0].deliver_frames(frames)
                return
            for frame in frames:
                for direct in directs:
                    direct.deliver_frames((frame,))
            return
        # a receiver that wants messages (python-can's bus, a listener of yours, this bus)
        for frame in frames:
            self.send(message_of(frame))

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        msg, filtered = super()._recv_internal(timeout)
        if msg is not None and msg.is_fd and not self._fd:
            return None, False      # unheard (hil.can.fd_option); recv waits on
        return msg, filtered

    def shutdown(self) -> None:
        with _DIRECT_LOCK:
            _DIRECT.pop(self.queue, None)
        super().shutdown()
