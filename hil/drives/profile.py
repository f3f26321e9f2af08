"""The seam between a drive's CAN protocol and its :class:`~hil.drives.core.DriveCore`.

Like python-can's ``BusABC``: one narrow abstract interface, the shared behaviour in the
base, concrete drives found through their protocol (:func:`hil.protocols.protocol`).
Physics, limits, faults, the watchdog and the brake live in the core; a drive profile only
turns frames into core commands and core state into frames.

Every profile uses a ``canopen.Network`` as its bus (:mod:`hil.can.network`): a frame
dispatcher by arbitration id over a python-can bus, whatever the protocol.

Cycle contract with the simulator: when a drive receives its cyclic command
(SYNC for CiA 402, a command frame for MIT and ODrive), it applies it,
samples the state its reply will carry, and calls :attr:`on_command`. In
real time the simulator answers at once (:meth:`send_replies`); in lock-step
it first advances the plant one control period, once every drive has had its
command.
"""

from __future__ import annotations

import logging
import time
from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from contextlib import AbstractContextManager
from dataclasses import dataclass
from typing import ClassVar

import can
import canopen

from hil.can.network import CanopenNetwork
from hil.drives.core import DriveCore
from hil.drives.definitions import Fault
from hil.protocols.base import Protocol

log = logging.getLogger(__name__)


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
            self._lost(can_id, 1, exc)

    def send_frames(self, frames: Sequence[tuple[int, bytes]]) -> None:
        try:
            super().send_frames(frames)
        except can.CanError as exc:     # from a bus taking them all at once: all lost
            self._lost(frames[0][0], len(frames), exc)

    def _lost(self, can_id: int, count: int, exc: can.CanError) -> None:
        before, self.lost_frames = self.lost_frames, self.lost_frames + count
        # the first, the 1001st, ...: whichever of them this loss counted
        if (before - 1) // self.LOG_EVERY != (self.lost_frames - 1) // self.LOG_EVERY:
            log.warning("a drive's frame 0x%03X was lost (%d so far): %s", can_id,
                        self.lost_frames, exc)


#: what a :class:`Reading` measures; None for what must match exactly (states, codes)
QUANTITIES = ("position", "velocity", "torque", "derived")


@dataclass(frozen=True)
class Reading:
    """One value a drive's frame carries, decoded for a replay's comparison (:mod:`hil.replay`).

    ``quantity`` says what it measures (one of QUANTITIES: the motor's position, velocity or
    torque, or a value derived from them, such as a current or a power) or None for what
    must match exactly; ``scale`` turns ``value`` (as the frame carries it) into SI units at
    the motor (rad, rad/s, N·m)."""

    name: str
    value: float
    quantity: str | None = None
    scale: float = 1.0


class DriveProfile(ABC):
    """A virtual drive on a bus, speaking one protocol, around a DriveCore."""

    #: the protocol it speaks
    protocol: ClassVar[type[Protocol]]

    def __init__(self, node_id: int, core: DriveCore, lock: AbstractContextManager):
        """``lock`` is held around everything a frame does to the drive; its owner holds it
        while stepping the physics (the simulator's also brings the plant up to the present
        on entry: hil.simulator.PlantPresent)."""
        profile = type(self)
        if (profile.take_replies is DriveProfile.take_replies
                and profile.send_replies is DriveProfile.send_replies):
            # ABC's refusal of a class with an abstract method left, for a pair of which
            # either will do
            raise TypeError(f"Can't instantiate {profile.__name__}: it defines neither "
                            "take_replies nor send_replies")
        self.node_id = node_id
        self.core = core
        self.lock = lock
        self.network: canopen.Network | None = None
        #: called (lock held) when this cycle's command has arrived; set by the simulator
        self.on_command: Callable[[DriveProfile], None] = lambda drive: None
        self.malformed = 0          # frames refused (wrong length, bad values)
        #: the clock the drive's frames feed its watchdog on: the simulator checks the
        #: watchdogs on time.monotonic too; a lock-step test steps a clock of its own
        self.clock: Callable[[], float] = time.monotonic

    # --- what a profile must say ----------------------------------------------------

    @abstractmethod
    def subscriptions(self) -> dict[int, Callable[[int, bytes, float], None]]:
        """The arbitration ids this drive listens to, with their handlers."""

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

    def heard(self) -> None:
        """A frame for this drive arrived: the watchdog's sign of life, whatever the frame
        (lock held). Where a protocol's firmware counts only some frames, its profile feeds
        on those instead."""
        self.core.new_setpoint(now=self.clock())

    def send(self, can_id: int, data: bytes, remote: bool = False) -> None:
        """Send a frame, if on a bus."""
        if self.network is not None:
            self.network.send_message(can_id, data, remote)

    # --- the reply to a cycle's command: a profile defines one of the two --------------

    def take_replies(self) -> list[tuple[int, bytes]] | None:
        """The reply to this cycle's command, as sampled when it arrived: its frames
        (arbitration id, data), each taken once, which the simulator sends with the other
        replies of the bus in one go. None (this default): the profile sends its reply
        itself (:meth:`send_replies`)."""
        return None

    def send_replies(self) -> None:
        """Send the reply to this cycle's command, as sampled when it arrived (by default the
        frames of :meth:`take_replies`), if on a bus."""
        replies = self.take_replies()
        if replies and self.network is not None:
            self.network.send_frames(replies)

    def after_update(self) -> None:
        """After each plant step (lock held): report new faults, state follow-ups."""

    def take_events(self) -> list[Fault]:
        """The faults the core raised since the last call, each logged: the drive's own
        account, on the simulator's console, of why it stopped (lock held)."""
        events = self.core.events
        if events:
            self.core.events = []
            for fault in events:
                log.warning("node %d: %s (0x%04X)", self.node_id, fault.text, fault.code)
        return events

    def restart(self) -> None:
        """Restart as after a power cycle (lock held): disabled, faults cleared; a protocol
        with a boot sequence of its own boots again, unconfigured."""
        self.core.disable()
        self.core.reset_fault()

    def tick(self, now: float) -> None:
        """Timer-driven frames due at monotonic time ``now`` (lock held), in real time."""

    @property
    def state_text(self) -> str:
        """The drive's state in its protocol's words."""
        return self.core.power.name

    # --- what a replay compares (hil.replay) -------------------------------------------

    def timed(self, can_id: int, data: bytes) -> bool:
        """Whether this frame of the drive's is one it sends on its own clock (a heartbeat,
        a timed message), not in answer to its master: a replay checks what it reports
        against :meth:`timed_content`, not frame by frame."""
        return False

    def timed_ids(self) -> tuple[int, ...]:
        """The ids of the timed frames whose content is the drive's state (its heartbeat)."""
        return ()

    def timed_content(self, can_id: int) -> bytes | None:
        """What the drive would send now on one of :meth:`timed_ids` (its state)."""
        return None

    def readings(self, can_id: int, data: bytes) -> tuple[Reading, ...] | None:
        """The values one of this drive's own frames carries, for a comparison within
        tolerances; None: the frame is compared byte for byte (an SDO answer, an EMCY)."""
        return None
