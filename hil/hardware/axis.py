"""The master's side of one drive: the seam between the CAN master and a protocol.

:class:`CanHardwareInterface` drives every axis the same way: reset, wait
until it is heard, configure, then each cycle send :meth:`Axis.cycle_frames`
and wait for :attr:`Axis.feedback` of that cycle; :meth:`Axis.fault` says
what is wrong, as an :class:`AxisFault`. The concrete axes (found through their protocol,
:func:`hil.protocols.protocol`) only turn these into their protocol's frames and
back, in motor units (rad, rad/s, N·m).
"""

from __future__ import annotations

import enum
import functools
import threading
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import ClassVar, NamedTuple

from mypy_extensions import mypyc_attr

from hil.bus_config.types import DriveConfig
from hil.can.frame import Frame
from hil.can.router import FrameRouter, Subscription
from hil.protocols.base import Protocol

#: fraction of the max velocity below which an axis counts as still (enable only then)
STANDSTILL = 0.01


class FaultKind(enum.Enum):
    """What the master found wrong with a drive."""

    SILENT = "silent"                     # no answer for too many cycles, or not heard
    FAULT = "fault"                       # the drive is in its fault state
    QUICK_STOP = "quick stop"             # the drive quick-stopped on its own
    REPORTED = "reported"                 # an error the drive reported (EMCY), acted on alone
    DISARMED = "disarmed"                 # the drive disarmed itself with an error (ODrive)
    IMPLAUSIBLE = "implausible feedback"  # feedback no joint can produce
    REBOOTED = "rebooted"                 # booted again mid-run: it lost its configuration


@mypyc_attr(native_class=False)      # threading.Event's own attributes live in its __dict__
class BootFlag(threading.Event):
    """An axis' "heard from since reset" flag. Most families set it at every answer: a set
    that finds it set returns at once (``threading.Event.set`` takes the Event's lock and
    notifies each time, five interpreted calls an axis a cycle)."""

    def set(self) -> None:
        # threading.Event's own flag, what is_set() returns (not in typeshed's stub)
        if not self._flag:  # type: ignore[attr-defined]
            super().set()


class AxisCommand(NamedTuple):
    """What the master asks of one axis this cycle, in motor units. (A named tuple: one is
    made per axis per cycle, and a frozen dataclass' constructor sets each field through
    ``object.__setattr__``.)"""

    #: where to follow (rad)
    target: float
    #: the target's velocity (rad/s), where the protocol carries one
    velocity: float
    #: a torque feed-forward (N·m), for drives whose config asks for one; given only to axes
    #: of protocols that declare ``carries_torque_feed_forward``
    torque: float = 0.0
    #: bring the axis to rest (a stop or a fault: the drives are being stopped)
    stopping: bool = False
    #: hold where it is (enabling, or recovering after a reset) instead of following
    holding: bool = False


#: an AxisCommand from the tuple of all its fields, by tuple.__new__ from C: the named tuple's
#: own __new__ is a Python function, run an axis and cycle (docs/performance.md, "2026-12-01:
#: the in-process cycle in a fifth fewer instructions")
command_of = functools.partial(tuple.__new__, AxisCommand)


@dataclass(frozen=True)
class AxisFault:
    """A fault the master found: which drive (bus, node, joints), what kind, the drive's own
    error code where it sent one (CiA 301 EMCY code, ODrive axis error). ``str()`` is the
    sentence for people, naming the drive and joints."""

    kind: FaultKind
    bus: str
    node_id: int
    joints: tuple[str, ...]
    message: str
    code: int | None = None
    #: a silence: how long the drive had not answered when it was found (s)
    silent_for: float | None = None

    def __str__(self) -> str:
        return self.message


@dataclass
class AxisFeedback:
    position: float = 0.0      # rad, motor
    velocity: float = 0.0      # rad/s, motor
    torque: float = 0.0        # N·m, motor
    cycle: int = -1            # the master cycle whose answer this is
    heard: bool = False        # an answer has set the values (until then they are defaults)


@mypyc_attr(allow_interpreted_subclasses=True)     # every protocol's axis not compiled
class Axis(ABC):
    """One drive as the master sees it."""

    #: the protocol it speaks
    protocol: ClassVar[type[Protocol]]
    #: the least time a bring-up request waits for its answer (s), where that is longer
    #: than its protocol's own default: the master's reply timeout (in lock-step a stalled
    #: drive is slow, not dead)
    request_timeout: float = 0.0

    def __init__(self, config: DriveConfig, bus_name: str, on_feedback=lambda: None):
        self.config = config
        self.bus_name = bus_name
        self.node_id = config.node_id
        self.label = (f"drive node {config.node_id} ({', '.join(config.joints)}) on bus "
                      f"'{bus_name}'")
        self.feedback = AxisFeedback()
        self.router: FrameRouter | None = None
        self.last_heard = time.monotonic()      # the drive's last sign of life
        self.booted = BootFlag()                 # heard from since reset()
        #: configured (:meth:`configure` done) and not heard booting again since
        self.configured = False
        #: heard booting again after it was configured (a power cycle, its host restarted):
        #: set by a protocol that can tell; it follows nothing until configured again
        self.rebooted = False
        self._cycle = 0
        self._on_feedback = on_feedback          # called when a cycle's answer is in

    # --- what a protocol must say -------------------------------------------------------

    @abstractmethod
    def subscriptions(self) -> list[Subscription]:
        """The frames this axis listens to, each with its handler."""

    @abstractmethod
    def cycle_frames(self, command: AxisCommand) -> list[Frame]:
        """This cycle's frames: walk toward following the command's target unless it is
        stopping (then bring the axis to rest); while it is holding, hold where it is."""

    @property
    @abstractmethod
    def state(self) -> str:
        """The drive's state in its protocol's words."""

    @property
    @abstractmethod
    def enabled(self) -> bool:
        """Whether the drive follows setpoints."""

    # --- shared behaviour -----------------------------------------------------------

    def attach(self, router: FrameRouter) -> None:
        """Listen on the bus of ``router`` and send through it."""
        self.router = router
        for subscription in self.subscriptions():
            subscription.join(router)

    def reset(self) -> None:
        """Ask the drive to start afresh; :attr:`booted` is set once it is heard."""
        self.booted.clear()

    def configure(self) -> None:
        """After boot: check the drive and select cyclic position control (then
        :attr:`configured`)."""

    def disable_rounds(self) -> list[list[Frame]]:
        """Frames that leave the drive disabled, in rounds sent a cycle or two apart."""
        return []

    def fault(self, stopping: bool = False) -> AxisFault | None:
        """Why this axis cannot be used (a quick stop counts only when not ``stopping``), or
        None."""
        return None

    def found(self, kind: FaultKind, what: str, code: int | None = None,
              silent_for: float | None = None) -> AxisFault:
        """A fault of this axis: ``what`` follows its label in the message."""
        return AxisFault(kind, self.bus_name, self.node_id, self.config.joints,
                         f"{self.label} {what}", code, silent_for)

    def forget_faults(self) -> None:
        """Before a fault reset: forget what the drive reported."""

    @property
    def silence_limit(self) -> float:
        """Seconds without a sign of life after which the drive counts as gone."""
        return 3 * self.config.heartbeat_period

    def begin_cycle(self, cycle: int) -> None:
        self._cycle = cycle

    def at_standstill(self) -> bool:
        """Fresh feedback (last cycle's) and not moving: safe to enable here."""
        return (self.feedback.heard and self.feedback.cycle >= self._cycle - 1
                and abs(self.feedback.velocity) <= STANDSTILL * self.config.max_velocity)

    def answered(self) -> None:
        """The cycle's answer is in: record it and wake the master."""
        self.last_heard = time.monotonic()   # before the cycle mark the master may wake on
        self.feedback.heard = True
        self.feedback.cycle = self._cycle
        self._on_feedback()


def answers_of(axes: list[Axis]) -> tuple[list[float], tuple[str, ...]]:
    """The axes' last answers (motor side, in their order): every position, then every
    velocity, then every torque, in one list; and each axis' state. Here, compiled, where the
    master reads them each cycle: a walk over the axes and four of their fields each."""
    positions: list[float] = []
    velocities: list[float] = []
    torques: list[float] = []
    states: list[str] = []
    for axis in axes:
        feedback = axis.feedback
        positions.append(feedback.position)
        velocities.append(feedback.velocity)
        torques.append(feedback.torque)
        states.append(axis.state)
    positions += velocities
    positions += torques
    return positions, tuple(states)
