"""The seam between a drive's CAN protocol and its :class:`~hil.drives.core.DriveCore`.

Like python-can's ``BusABC``: one narrow abstract interface, the shared behaviour in the
base, concrete drives found through their protocol (:func:`hil.protocols.protocol`).
Physics, limits, faults, the watchdog and the brake live in the core; a drive profile only
turns frames into core commands and core state into frames.

Every profile talks through its bus' :class:`~hil.can.router.FrameRouter` (the drives' side
of it loses a frame the bus refuses, as a drive's CAN controller does, and runs on): it
subscribes its handlers by identifier and sends :class:`~hil.can.frame.Frame` values.

Cycle contract with the simulator: when a drive receives its cyclic command
(SYNC for CiA 402, a command frame for MIT and ODrive), it applies it,
samples the state its reply will carry, and calls :attr:`on_command`. In
real time the simulator answers at once (:meth:`take_replies`, sent as its lock is
left, a bus' answers to one delivery together; or :meth:`send_replies`); in lock-step
it first advances the plant one control period, once every drive has had its
command.
"""

from __future__ import annotations

import logging
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from contextlib import AbstractContextManager
from dataclasses import dataclass
from typing import ClassVar

from mypy_extensions import mypyc_attr

from hil.bus_config.types import BusConfig, DriveConfig
from hil.can.frame import Frame
from hil.can.router import FrameRouter, Subscription
from hil.drives.core import DriveCore
from hil.drives.definitions import Fault
from hil.protocols.base import Protocol

log = logging.getLogger(__name__)


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


@mypyc_attr(allow_interpreted_subclasses=True)     # every protocol's drive not compiled
class DriveProfile(ABC):
    """A virtual drive on a bus, speaking one protocol, around a DriveCore."""

    #: the protocol it speaks
    protocol: ClassVar[type[Protocol]]
    #: whether :meth:`after_update` has work after every plant step (its protocol's state
    #: follow-ups); False: only after a step that left the core faults to report (its
    #: ``events``), the only steps after which the simulator calls it then (a call a drive a
    #: step saved: two calls a drive a cycle of a 500 Hz bus on a 1 kHz plant)
    follows_every_step: ClassVar[bool] = False

    def __init__(self, config: DriveConfig, core: DriveCore, lock: AbstractContextManager):
        """The drive of ``config`` (its node id, ratings, heartbeat and the protocol's
        ``options``) around ``core``. ``lock`` is held around everything a frame does to the drive; its owner holds it
        while stepping the physics (the simulator's also brings the plant up to the present
        on entry: hil.realtime.present.PlantPresent)."""
        profile = type(self)
        if (profile.take_replies is DriveProfile.take_replies
                and profile.send_replies is DriveProfile.send_replies):
            # ABC's refusal of a class with an abstract method left, for a pair of which
            # either will do
            raise TypeError(f"Can't instantiate {profile.__name__}: it defines neither "
                            "take_replies nor send_replies")
        self.config = config
        self.node_id = config.node_id
        self.core = core
        self.lock = lock
        self.router: FrameRouter | None = None
        #: called (lock held) when this cycle's command has arrived; set by the simulator
        self.on_command: Callable[[DriveProfile], None] = lambda drive: None
        self.malformed = 0          # frames refused (wrong length, bad values)
        #: the clock the drive's frames feed its watchdog on: the simulator checks the
        #: watchdogs on time.monotonic too; a lock-step test steps a clock of its own
        self.clock: Callable[[], float] = time.monotonic

    # --- what a profile must say ----------------------------------------------------

    @abstractmethod
    def subscriptions(self) -> list[Subscription]:
        """The frames this drive listens to, each with its handler."""

    # --- shared behaviour ------------------------------------------------------------

    def on_bus(self, bus: BusConfig) -> None:
        """Built on ``bus``, before it is attached (the simulator's builder tells it): a
        profile whose frames follow the bus' (its CAN FD rates) reads it here."""

    @property
    def attached(self) -> bool:
        """On a bus; a detached drive is silent (its physics runs on)."""
        return self.router is not None

    def attach(self, router: FrameRouter) -> None:
        """Join a bus and start talking (boot-up, cyclic messages)."""
        self.router = router
        for subscription in self.subscriptions():
            subscription.join(router)

    def detach(self) -> None:
        """Leave the bus: from now on the drive sends and hears nothing (idempotent)."""
        if self.router is None:
            return
        for subscription in self.subscriptions():
            subscription.leave(self.router)
        self.router = None

    def heard(self) -> None:
        """A frame for this drive arrived: the watchdog's sign of life, whatever the frame
        (lock held). Where a protocol's firmware counts only some frames, its profile feeds
        on those instead."""
        self.core.new_setpoint(now=self.clock())

    def send(self, frame: Frame) -> None:
        """Send a frame, if on a bus."""
        if self.router is not None:
            self.router.send(frame)

    # --- the reply to a cycle's command: a profile defines one of the two --------------

    def take_replies(self) -> list[Frame] | None:
        """The reply to this cycle's command, as sampled when it arrived: its frames, each
        taken once, which the simulator sends with the other
        replies of the bus in one go. None (this default): the profile sends its reply
        itself (:meth:`send_replies`)."""
        return None

    def send_replies(self) -> None:
        """Send the reply to this cycle's command, as sampled when it arrived (by default the
        frames of :meth:`take_replies`), if on a bus."""
        replies = self.take_replies()
        if replies and self.router is not None:
            self.router.send_frames(replies)

    def after_update(self) -> None:
        """After a plant step (lock held): report new faults, state follow-ups (after every
        step where :attr:`follows_every_step`, else after a step that left core events)."""

    def take_events(self) -> list[Fault]:
        """The faults the core raised since the last call, each logged: the drive's own
        account, on the simulator's console, of why it stopped (lock held)."""
        events = self.core.events
        if events:
            self.core.events = []
            for fault in events:
                log.warning("node %d: %s", self.node_id, self.fault_words(fault))
        return events

    def fault_words(self, fault: Fault) -> str:
        """A fault as the drive's log says it: the core's words, and where the protocol
        has one, its own code for it."""
        return fault.text

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

    def timed(self, frame: Frame) -> bool:
        """Whether this frame of the drive's is one it sends on its own clock (a heartbeat,
        a timed message), not in answer to its master: a replay checks what it reports
        against :meth:`timed_content`, not frame by frame."""
        return False

    def timed_ids(self) -> tuple[int, ...]:
        """The identifiers of the timed frames whose content is the drive's state (its
        heartbeat)."""
        return ()

    def timed_content(self, identifier: int) -> bytes | None:
        """What the drive would send now on one of :meth:`timed_ids` (its state)."""
        return None

    def readings(self, frame: Frame) -> tuple[Reading, ...] | None:
        """The values one of this drive's own frames carries, for a comparison within
        tolerances; None: the frame is compared byte for byte (an SDO answer, an EMCY)."""
        return None
