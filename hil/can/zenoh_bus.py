"""A python-can interface that carries CAN frames over Zenoh.

Registered as python-can interface ``zenoh`` (entry point group ``can.interface``), so
``can.Bus(interface="zenoh", channel="ur3/arm")`` works in any program. Every bus on the
same channel, in any process that reaches the same Zenoh network, sees every frame the
others send, in order per sender, like a CAN bus; a bus does not receive its own frames
unless ``receive_own_messages=True``. There is no arbitration or bandwidth limit: ``hil
check`` estimates the load a real bus would carry.

Why: SocketCAN ``vcan`` needs a Linux kernel with CAN; python-can's ``virtual`` bus is one
process only and ``udp_multicast`` sends to the network. Zenoh over loopback TCP is
cross-process, loopback-only by default, and lets drives and controller run on two hosts.

Back-pressure, as a CAN controller has it: a send never blocks its thread (a drive answers
from inside a delivery, holding the simulator's lock): under congestion Zenoh drops the
frame (``CongestionControl.DROP``, after at most ``hil.zenoh_session.DROP_WAIT_US``).
``lossless=True`` (hil's processes in lock-step, which keep no deadline) waits for room
instead (``CongestionControl.BLOCK``), and at shutdown for the monitors to have heard its
last frame (:mod:`hil.can.zenoh_receipts`): a monitor that falls behind (``hil viz`` on a
loaded host) slows the run rather than lose frames of its log, which a replay compares.
Frames reach other processes only; buses of one process that share a session hand each
other their frames in the sender's thread. One subscriber per session feeds all of a
process' buses, which deliver to a bounded FIFO for ``recv`` (an overrun is counted) or
straight to listeners (``deliver_to``); every frame carries its sender's sequence number,
so a receiver counts what was lost on the way (docs/design.md: why each choice).

Between hil's own ends a frame stays a :class:`~hil.can.frame.Frame` from the sender's
router (``frame_sender``) to the receiver's (``deliver_frames``): a ``can.Message`` is
built only where one is wanted (``recv``, a listener of yours).

Frames sent together (inside ``with bus.batch():``, or in answer to a message being
delivered) go in one Zenoh message of a section per bus (docs/design.md, "The Zenoh CAN
transport", says why).

Each section carries the sender's clock at the put and echoes the message its sender
heard last, so that a receiver tells a late delivery (a stall of the transport) and a slow
link (a stall of the link) from a late process, and has the link's round trip
(``watch_stalls``; :mod:`hil.can.link_account`, the account a bus keeps of its link).

The wire format is :mod:`hil.can.zenoh_wire`'s; what a bus counts, :mod:`hil.can.link_statistics`'.
"""

from __future__ import annotations

import logging
import os
import queue
import random
import threading
import time
import weakref
from collections.abc import Callable, Iterable, Sequence
from contextlib import AbstractContextManager
from pathlib import Path

import can
import zenoh

from hil.can.capabilities import BusCapabilities
from hil.can.delivery import DirectDelivery
from hil.can.fd_option import fd_protocol, refuse_fd_send, takes_fd
from hil.can.frame import Frame
from hil.can.link_account import LinkAccount
from hil.can.messages import frame_of, message_of
from hil.can.zenoh_channels import Channels
from hil.can.zenoh_links import not_linked
from hil.can.zenoh_receipts import LINGER, wait_until_heard
from hil.can.zenoh_wire import KEY_PREFIX, Message, encode_frames
from hil.realtime.stalls import Stall
from hil.zenoh_session import ZenohSettings, session, why_unreached

log = logging.getLogger(__name__)

#: frames a bus holds for ``recv`` before it drops new ones (a CAN controller's RX FIFO)
RECEIVE_FIFO = 8192
#: a malformed payload is logged the first time, then every this many
LOG_EVERY = 1000
#: how long opening a bus waits to be linked to every peer on its channel (s): hil's choice,
#: where gossip linked a new peer within milliseconds on an idle host and a loaded CI host
#: took long enough for a one-shot frame to go unheard (the ``link_timeout`` option)
LINK_TIMEOUT = 20.0


#: buses not shut down yet: shut down at exit (see _shut_down_at_exit)
_open_buses: weakref.WeakSet[ZenohBus] = weakref.WeakSet()


def _shut_down_at_exit() -> None:
    """Shut down every bus still open. Zenoh delivers in a thread that is no daemon and
    ends only when its subscriber goes, and Python joins such threads before atexit
    handlers run: a script that never called ``bus.shutdown()`` hung at exit for good.
    Registered with ``threading._register_atexit`` (what concurrent.futures uses), which
    runs before that join."""
    for bus in list(_open_buses):
        bus.shutdown()


threading._register_atexit(_shut_down_at_exit)


class ZenohBus(can.BusABC, BusCapabilities):
    """python-can bus over Zenoh pub/sub on key ``hil/can/<channel>``.

    Options: ``listen`` / ``connect`` (lists of Zenoh endpoints; with neither, nor a config
    file, the bus joins the hil processes of this host at their meeting point:
    :func:`hil.zenoh_session.meeting_endpoint`), ``zenoh_config`` (path of a Zenoh config
    file), ``receive_own_messages``; ``settings`` (a :class:`ZenohSettings`, in place of the
    three: how hil's own processes join their session, ``--secure`` included);
    ``timestamps``: what a received frame's timestamp is, ``"arrival"`` (this process'
    clock when it came) or ``"sent"`` (its sender's clock when it was put: when it was on
    the bus, as an interface on the bus stamps it; what a log of the bus wants, the logger
    being a process that may be late); ``lossless``: a send waits for room in a congested
    link instead of dropping the frame (see the module doc); ``link_timeout`` (s): how long
    the open may wait to be linked to every peer on the channel (:meth:`_await_links`).
    ``fd``: it sends and hears CAN FD frames, as a SocketCAN socket (:mod:`hil.can.fd_option`).
    ``watch_stalls`` sets who is told (in Zenoh's delivering thread) of each late delivery.
    """

    def __init__(self, channel: str, listen=(), connect=(), zenoh_config=None,
                 receive_own_messages: bool = False, settings: ZenohSettings | None = None,
                 timestamps: str = "arrival", lossless: bool = False,
                 link_timeout: float | str = LINK_TIMEOUT, fd: bool = False, **kwargs):
        self.channel_info = f"Zenoh {KEY_PREFIX}{channel}"
        protocol = fd_protocol(fd, kwargs)
        self._fd = takes_fd(protocol)           # hil.can.fd_option
        self._channel = str(channel)
        if len(self._channel.encode()) > 255:
            raise ValueError(f"channel '{channel}': a name of at most 255 bytes (UTF-8)")
        if timestamps not in ("arrival", "sent"):
            raise ValueError(f"timestamps '{timestamps}': 'arrival' or 'sent'")
        link_timeout = float(link_timeout)      # python-can's config files give strings
        #: a log's bus (stamped with the senders' clocks): it answers for what it heard
        self.monitors = timestamps == "sent"
        self._lossless = lossless
        self._receive_own = receive_own_messages
        self._sender = random.getrandbits(63) ^ os.getpid()
        self._sequence = 0
        self._account = LinkAccount(self._sender, self._channel)
        self.counters = self._account.counters
        self._on_stall: Callable[[Stall], None] | None = None
        self._queue: queue.Queue[can.Message] = queue.Queue(RECEIVE_FIFO)
        self._direct: DirectDelivery | None = None
        if settings is None:
            settings = (ZenohSettings(tuple(listen), tuple(connect),
                                      Path(zenoh_config) if zenoh_config else None)
                        if listen or connect or zenoh_config else ZenohSettings.meeting())
        self._settings = settings
        self._session = session(settings)
        key = KEY_PREFIX + self._channel
        # not express: Zenoh batches what a burst puts before its TX task sends it. Measured on
        # loopback (8 frames answered by 12, as a cycle of the ur3): a cycle's round trip and
        # each put shorter batched; a lone frame's round trip the same either way, Zenoh's
        # batch time limit does not hold it back (docs/performance.md,
        # "How the cycle got here (measured at the time, on earlier commits)").
        # DROP: a put never blocks (lossless, BLOCK: it waits for room); REMOTE: see the
        # module doc
        self._publisher = self._session.declare_publisher(
            key, congestion_control=zenoh.CongestionControl.BLOCK if lossless
            else zenoh.CongestionControl.DROP, express=False,
            allowed_destination=zenoh.Locality.REMOTE)
        self._key = key
        self._channels, self._neighbours = Channels.join(self._session, key, self)
        super().__init__(channel=channel, **kwargs)
        self._can_protocol = protocol
        _open_buses.add(self)
        self._await_links(link_timeout)

    def _await_links(self, timeout: float) -> None:
        """Return once this bus' session is linked directly to every peer already on the
        channel (:mod:`hil.can.zenoh_links`): a frame sent at once reaches them all, as on a
        CAN bus once it is open; else, after ``timeout`` s, shut down and raise
        CanInitializationError naming the peers."""
        unlinked = self._channels.links[self._key].wait_linked(timeout)
        if unlinked:
            self.shutdown()
            raise can.CanInitializationError(not_linked(self.channel_info, unlinked, timeout))

    def watch_stalls(self, on_stall: Callable[[Stall], None] | None) -> None:
        self._on_stall = on_stall

    def heard(self) -> dict[int, int]:
        """Each sender's last sequence number heard."""
        return self._account.heard()

    def unreached(self) -> str | None:
        """Why this bus' session reaches no other process, in words, if it reaches none
        (:func:`hil.zenoh_session.why_unreached`)."""
        return why_unreached(self._settings)

    def _count_malformed(self, problem: ValueError) -> None:
        """A payload on this bus' key that was not a message: counted, and logged the first
        time and every LOG_EVERY."""
        malformed = self._account.malformed()
        if malformed % LOG_EVERY == 1:
            log.warning("%s: dropped %d malformed message(s) from Zenoh: %s",
                        self.channel_info, malformed, problem)

    def _on_message(self, message: Message, arrived: float, now: float) -> None:
        """A section of a message for this bus' channel, arrived at ``arrived`` (wall clock)
        and ``now`` (monotonic)."""
        stalls = self._account.arrived(message, arrived, now)
        on_stall = self._on_stall
        if stalls and on_stall is not None:
            for stall in stalls:
                on_stall(stall)
        self._take(message.frames, message.sent_at if self.monitors else arrived)

    def _take(self, frames: Sequence[Frame], timestamp: float, is_rx: bool = True) -> None:
        """Frames for this bus, to the listeners (as they are where they all take frames)
        or the receive FIFO (as messages stamped ``timestamp``)."""
        direct = self._direct
        if direct is not None:
            if direct.takes_frames:
                direct.deliver_frames(frames)
                return
            for frame in frames:
                direct.deliver(message_of(frame, self._channel, is_rx, timestamp))
            return
        for frame in frames:
            try:
                self._queue.put_nowait(message_of(frame, self._channel, is_rx, timestamp))
            except queue.Full:
                self._account.overrun()

    def deliver_to(self, listeners: Iterable[can.Listener],
                   accept: Callable[[can.Message], can.Message | None] | None = None
                   ) -> DirectDelivery:
        """From now on give this bus' received frames to ``listeners`` in Zenoh's callback
        thread (after ``accept``, which may change a frame or return None to drop it), in
        the order they arrive: no queue, and no Notifier thread woken for every frame."""
        self._direct = DirectDelivery(listeners, accept, self._stop_delivery)
        return self._direct

    def deliver_under(self, guard: AbstractContextManager | None) -> None:
        """From now on each message for the buses of this bus' session is delivered inside
        ``guard`` (entered once per message, whatever its frames; None: none): a simulator's
        plant lock, so that the plant steps up to the present once a message, not once a
        frame (12 entries a cycle of the ur3, each looking at the clock)."""
        self._channels.guard = guard

    def _stop_delivery(self, delivery: DirectDelivery) -> None:
        if self._direct is delivery:
            self._direct = None

    def batch(self) -> AbstractContextManager:
        """Frames this thread sends inside the block, on this bus and on every other bus of
        its Zenoh session, go out in one message at its end (nested blocks: at the
        outermost's end), in the order sent. Every bus of a session returns the same block,
        so that :func:`hil.can.held_together` enters it once for them all."""
        return self._channels.together

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if msg.is_fd and not self._fd:
            refuse_fd_send(self.channel_info, msg)
        frame = frame_of(msg)
        problem = frame.problem()     # hil's own senders' frames are valid by construction
        if problem is not None:
            raise can.CanOperationError(f"{self.channel_info}: cannot send {frame}: {problem}")
        self.send_frames((frame,))

    def frame_sender(self) -> Callable[[Sequence[Frame]], None]:
        return self.send_frames

    def send_frames(self, frames: Sequence[Frame]) -> None:
        """Send frames, in order: held for the batch's message inside :meth:`batch`, else in
        a message of their own."""
        if self._is_shutdown:
            raise can.CanOperationError(f"{self.channel_info}: the bus is shut down")
        # a list of its own: the sender may reuse its list once this returns, before the
        # batch's put (a frame itself is immutable)
        frames = list(frames)
        channels = self._channels
        outbox = channels.outbox
        if outbox.depth:
            held = outbox.held.get(self)
            if held is None:
                outbox.held[self] = frames
            else:
                held.extend(frames)
        else:
            channels.put({self: frames})

    def _section(self, frames: Sequence[Frame], sent_at: float, now: float
                 ) -> tuple[int, bytes]:
        """This bus' section of a message of ``frames`` put now (under the session's send lock,
        so that its numbers keep the order of the puts): its first sequence number and bytes."""
        first = self._sequence + 1
        self._sequence += len(frames)
        echo = self._account.sent(first, len(frames), now)
        return first, encode_frames(self._channel, self._sender, first, sent_at, frames, echo)

    def _to_neighbours(self, first: int, frames: Sequence[Frame]) -> None:
        """Frames sent (the first numbered ``first``) to this process' buses on this channel
        (Zenoh carries them to other processes only)."""
        neighbours = [neighbour for neighbour in tuple(self._neighbours)
                      if neighbour is not self or self._receive_own]
        if not neighbours:
            return
        for neighbour in neighbours:
            neighbour._account.count(self._sender, first, len(frames), 0.0, 0.0)
            neighbour._take(frames, time.time(), neighbour is not self)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        try:
            msg = self._queue.get(timeout=timeout)
        except queue.Empty:
            return None, False
        if msg.is_fd and not self._fd:
            return None, False      # unheard (hil.can.fd_option); recv waits on
        return msg, False

    def shutdown(self) -> None:
        if self._is_shutdown:
            return
        super().shutdown()        # stops the periodic tasks; later sends are refused
        if self._lossless and self._sequence:
            behind = wait_until_heard(self._session, self._channel, self._sender,
                                      self._sequence)
            if behind:
                log.warning("%s: %d monitor(s) had not heard its last frames after %g s: "
                            "their logs end short of them", self.channel_info, behind, LINGER)
        # not under the send lock: a delivery in progress may still be answering
        Channels.leave(self._session, self._key, self)
        # a put still running in another thread ends first: zenoh refuses to undeclare a
        # publisher in use ("Already borrowed")
        with self._channels.send_lock:
            self._publisher.undeclare()
