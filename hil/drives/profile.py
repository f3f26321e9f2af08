"""The seam between a drive's CAN protocol and its :class:`~hil.drives.core.DriveCore`.

Like python-can's ``BusABC``: one narrow abstract interface, the shared
behaviour in the base, concrete profiles picked by a string
(``PROFILES[protocol]``). Physics, limits, faults, the watchdog and the
brake live in the core; a profile only turns frames into core commands and
core state into frames.

Every profile uses a ``canopen.Network`` as its bus: python canopen's
network is a frame dispatcher by arbitration id (``subscribe``) over a
python-can bus with a Notifier, whatever the protocol.

Cycle contract with the simulator: when a drive receives its cyclic command
(SYNC for CiA 402, a command frame for MIT and ODrive), it applies it,
samples the state its reply will carry, and calls :attr:`on_command`. In
real time the simulator answers at once (:meth:`send_replies`); in lock-step
it first advances the plant one control period, once every drive has had its
command.
"""

from __future__ import annotations

import logging
from abc import ABC, abstractmethod
from collections.abc import Callable
from contextlib import AbstractContextManager
from typing import ClassVar

import can
import canopen

from hil.can.messages import data_frame
from hil.drives.core import DriveCore

log = logging.getLogger(__name__)


class NetworkListener(can.Listener):
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
    the ur3's lock-step cycle.
    :func:`start_network` puts one in place of canopen's, as ``network.frame_listener``.
    """

    LOG_EVERY = 1000

    def __init__(self, network: canopen.Network):
        self.subscribers = network.subscribers
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
            for callback in self.subscribers.get(msg.arbitration_id, ()):
                try:
                    callback(msg.arbitration_id, msg.data, msg.timestamp)
                except Exception as exc:
                    self._refuse(msg, callback, exc)

    def _refuse(self, msg: can.Message, callback, exc: Exception) -> None:
        self.refused += 1
        count = self._refused_by_id.get(msg.arbitration_id, 0) + 1
        self._refused_by_id[msg.arbitration_id] = count
        if count % self.LOG_EVERY == 1:
            log.warning("frame 0x%03X [%s] refused by %s: %s: %s (%d from this id so far)",
                        msg.arbitration_id, bytes(msg.data).hex(" "),
                        getattr(callback, "__qualname__", callback), type(exc).__name__, exc,
                        count)
        log.debug("frame 0x%03X refused", msg.arbitration_id, exc_info=exc)


class CanopenNetwork(canopen.Network):
    """canopen's Network, its frames built by :func:`hil.can.messages.data_frame`: the
    same ``can.Message`` in 60 % of the time (a ur3 cycle sends 20 frames)."""

    def send_message(self, can_id: int, data: bytes, remote: bool = False) -> None:
        # canopen's own send_message but for how the frame is built (canopen 2.4)
        if not self.bus:
            raise RuntimeError("Not connected to CAN bus")
        with self.send_lock:
            self.bus.send(data_frame(can_id, data, remote))
        self.check()


class DriveNetwork(CanopenNetwork):
    """The drives' side of a bus. A frame the bus refuses (its transmit queue full, the bus
    gone) is lost and counted in :attr:`lost_frames`, as a drive's CAN controller loses it,
    and the drive runs on: a send error must not stop the plant mid-step. (A master's
    ``canopen.Network`` raises instead: the controller must know.)"""

    #: first lost frame, then every this many, logged
    LOG_EVERY = 1000

    def __init__(self, bus: can.BusABC | None = None):
        super().__init__(bus)
        self.lost_frames = 0

    def send_message(self, can_id: int, data: bytes, remote: bool = False) -> None:
        try:
            super().send_message(can_id, data, remote)
        except can.CanError as exc:
            self.lost_frames += 1
            if self.lost_frames % self.LOG_EVERY == 1:
                log.warning("a drive's frame 0x%03X was lost (%d so far): %s", can_id,
                            self.lost_frames, exc)


def start_network(bus: can.BusABC, timeout: float = 0.1,
                  network_class: type[canopen.Network] = CanopenNetwork) -> canopen.Network:
    """A canopen network (of ``network_class``) on ``bus`` with its frames flowing and RTR
    frames routed: handed over in the thread that brings them where the bus can
    (``deliver_to``: hil-virtual, zenoh; see hil.can.delivery), else by a python-can
    Notifier (``network.notifier`` either way)."""
    network = network_class(bus)
    network.frame_listener = NetworkListener(network)
    network.listeners = [network.frame_listener]     # canopen's MessageListener replaced
    deliver_to = getattr(bus, "deliver_to", None)
    direct = deliver_to(network.listeners) if deliver_to is not None else None
    network.notifier = direct or can.Notifier(bus, network.listeners, timeout)
    return network


class DriveProfile(ABC):
    """A virtual drive on a bus, speaking one protocol, around a DriveCore."""

    #: the ``protocol`` string of bus configs
    protocol: ClassVar[str]
    #: whether the bus needs a CANopen SYNC producer for this drive
    uses_sync: ClassVar[bool] = False
    #: the profile's own settings in a bus config (a frozen dataclass with ``from_mapping``
    #: raising ValueError, and ``KEYS``)
    Options: ClassVar[type | None] = None
    #: the node ids the protocol can address
    node_ids: ClassVar[range] = range(1, 128)
    #: whether the drive faults on a following error (MIT and ODrive firmware do not)
    has_following_error: ClassVar[bool] = True

    def __init__(self, node_id: int, core: DriveCore, lock: AbstractContextManager):
        """``lock`` is held around everything a frame does to the drive; its owner holds it
        while stepping the physics (the simulator's also brings the plant up to the present
        on entry: hil.simulator.PlantPresent)."""
        self.node_id = node_id
        self.core = core
        self.lock = lock
        self.network: canopen.Network | None = None
        #: called (lock held) when this cycle's command has arrived; set by the simulator
        self.on_command: Callable[[DriveProfile], None] = lambda drive: None
        self.malformed = 0          # frames refused (wrong length, bad values)

    # --- the two things a profile must say ------------------------------------------

    @classmethod
    @abstractmethod
    def bus_frames(cls, node_id: int, cycle_hz: float, heartbeat_period: float, options=None
                   ) -> list[tuple[int, int, float]]:
        """Every (arbitration id, payload bytes, frames per second) this drive and its
        master use on the bus; rate 0 for ids used only on events. For bus load and for
        id collisions between drives."""

    @abstractmethod
    def subscriptions(self) -> dict[int, Callable[[int, bytes, float], None]]:
        """The arbitration ids this drive listens to, with their handlers."""

    @abstractmethod
    def send_replies(self) -> None:
        """Send the reply to this cycle's command, as sampled when it arrived."""

    @classmethod
    def shared_ids(cls, options=None) -> set[int]:
        """Ids that several drives of this protocol on one bus may use at once."""
        return set()

    def remote_subscriptions(self) -> dict[int, Callable[[int], None]]:
        """Remote (RTR) frame ids this drive answers, with their handlers."""
        return {}

    # --- shared behaviour ------------------------------------------------------------

    @property
    def attached(self) -> bool:
        """On a bus; a detached drive is silent (its physics runs on)."""
        return self.network is not None

    def attach(self, network: canopen.Network) -> None:
        """Join a bus and start talking (boot-up, cyclic messages)."""
        self.network = network
        for can_id, handler in self.subscriptions().items():
            network.subscribe(can_id, handler)
        network.frame_listener.remote_handlers.update(self.remote_subscriptions())

    def detach(self) -> None:
        """Leave the bus: from now on the drive sends and hears nothing (idempotent)."""
        if self.network is None:
            return
        for can_id, handler in self.subscriptions().items():
            if handler in self.network.subscribers.get(can_id, []):
                self.network.unsubscribe(can_id, handler)
        for can_id in self.remote_subscriptions():
            self.network.frame_listener.remote_handlers.pop(can_id, None)
        self.network = None

    def send(self, can_id: int, data: bytes, remote: bool = False) -> None:
        """Send a frame, if on a bus."""
        if self.network is not None:
            self.network.send_message(can_id, data, remote)

    def after_update(self) -> None:
        """After each plant step (lock held): report new faults, state follow-ups."""

    def tick(self, now: float) -> None:
        """Timer-driven frames due at monotonic time ``now`` (lock held), in real time."""

    @property
    def state_text(self) -> str:
        """The drive's state in its protocol's words."""
        return self.core.power.name
