"""The seam between hil and one drive protocol: what both sides of the bus know of it.

Like python-can's ``BusABC``: one narrow abstract class (:meth:`Protocol.bus_frames` is all
a protocol must say), the shared behaviour here, concrete protocols picked by a string
(:func:`hil.protocols.protocol`). A protocol's simulated drive (a
:class:`hil.drives.profile.DriveProfile`) and its master-side axis (a
:class:`hil.hardware.axis.Axis`) are named here as ``"module:Class"`` and imported on first
use: the controller process loads no simulated drive, the simulator no master.
"""

from __future__ import annotations

import enum
import importlib
import math
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any, ClassVar

from hil.can.frame import Frame, FrameSpec


class Sender(enum.Enum):
    """Which side of a bus sends a frame."""

    MASTER = "master"
    DRIVE = "drive"


class CanFd(enum.Enum):
    """Which frames a family's devices send and take (ISO 11898-1:2015's classical and FD
    frames). A classical CAN controller that is not FD-tolerant takes an FD frame for a
    malformed one and destroys it with an error frame (CiA's CAN FD guidance: such nodes
    cannot share a bus with FD traffic)."""

    #: classical frames only (hil's CiA 402, ODrive CANSimple, MIT, CubeMars)
    CLASSIC = "classic"
    #: classical frames on a classical bus; on an FD bus FD frames with the bit-rate switch
    FOLLOWS_BUS = "follows the bus"
    #: FD frames only: no place on a classical bus
    FD_ONLY = "FD only"


@dataclass(frozen=True)
class FrameSource:
    """Who sends a frame of a protocol, which drive it concerns and what it is."""

    sender: Sender
    #: the drive it comes from or is addressed to; None: every drive of the bus (a SYNC, a
    #: broadcast NMT command)
    node_id: int | None
    #: the frame in the protocol's own words ("TPDO1", "SDO answer", "Set_Input_Pos")
    what: str
    #: the master's frame that makes the drive(s) answer a cycle (a SYNC, a cyclic request)
    cycle: bool = False


@dataclass(frozen=True)
class DriveSetting:
    """What ``hil init`` knows of one drive when it writes the protocol's options, all at
    the drive (motor side, after the transmission)."""

    reach: float           # rad (m): the largest |position| the joint's range asks of it
    speed: float           # rad/s: the joint's velocity limit
    peak_torque: float     # N·m: the joint's effort limit
    kp: float              # N·m/rad: a critically damped position loop on its inertia
    kd: float              # N·m·s/rad
    model: str | None      # the product sized for it (a key of Protocol.models), if any


class PublishedFigures:
    """What a model of a geared actuator whose maker publishes rated and peak torque and a
    no-load speed at the output, but no rotor inertia, tells ``hil init`` (a mixin for a
    model dataclass with ``rated_torque``, ``peak_torque`` and ``top_rpm``, each None where
    the sources give none)."""

    rated_torque: float | None
    peak_torque: float | None
    top_rpm: float | None

    @property
    def sizes(self) -> bool:
        """Whether the sources give the figures ``hil init --motor`` sizes with."""
        return None not in (self.rated_torque, self.peak_torque, self.top_rpm)

    @property
    def no_load_speed(self) -> float:
        """rad/s at the output (the maker's no-load speed)."""
        return (self.top_rpm or 0.0) * 2 * math.pi / 60

    @property
    def reflected_inertia(self) -> float:
        """0: the sources give no rotor inertia (``hil init`` estimates one:
        ``hil.commissioning.sizing.estimated_reflected_inertia``)."""
        return 0.0


@dataclass(frozen=True)
class CarriedRange:
    """The largest position and velocity at the motor (after the product's own gear) that a
    product's frames carry: beyond them its commands and feedback saturate."""

    position: float        # rad: positions map onto [-position, position]
    velocity: float        # rad/s


@dataclass(frozen=True)
class SettingField:
    """Where a drive setting of the bus config travels in the product: a field holding
    ``round(value * scale)`` in ``low..high`` (named, with its source, for the message that
    refuses a value it cannot hold)."""

    scale: float
    low: int
    high: int
    field: str

    def holds(self, value: float) -> bool:
        return self.low <= round(value * self.scale) <= self.high


class ProtocolOptions:
    """A protocol's own settings in a bus config (``options:`` of a drive), with what hil
    asks of every protocol's settings declared here with its default."""

    #: keys whose values are files: the bus config parser makes them relative to the
    #: config's own directory before :meth:`from_mapping` sees them
    PATH_KEYS: ClassVar[tuple[str, ...]] = ()
    #: the product's own controller-silence timeout as it ships (s; 0: off): the default of
    #: a drive's ``watchdog_timeout`` (:meth:`drive_defaults`); None where the product has
    #: no CAN timeout of its own (the bus config's reader then takes hil's 0.1 s)
    WATCHDOG_TIMEOUT: ClassVar[float | None] = None

    @property
    def sends_velocity(self) -> bool:
        """Whether the master sends the trajectory's velocity beside each target (a
        feed-forward the bus load and the tracking depend on)."""
        return False

    def check_notes(self) -> list[str]:
        """What ``hil check`` says of these settings beyond the drive's table (the objects a
        vendor's EDS has that hil stores without acting on them). None by default."""
        return []

    def carried_range(self) -> CarriedRange | None:
        """What these settings' frames carry of position and velocity (MIT-style frames map
        a fixed range onto their fields), for ``hil check`` to hold against the joint's
        range and speed at the motor. None (the default): any the joint can ask."""
        return None

    def drive_defaults(self) -> dict[str, float | bool]:
        """Drive keys of the bus config (``peak_torque``, ``rated_torque``,
        ``max_velocity``, ``holding_brake``, ``watchdog_timeout``) that the product these
        settings name sets where the config does not: a motor model's published figures,
        the firmware's own timeout (:attr:`WATCHDOG_TIMEOUT`). None by default."""
        timeout = self.WATCHDOG_TIMEOUT
        return {} if timeout is None else {"watchdog_timeout": timeout}


class Protocol(ABC):
    """One drive protocol: its name in bus configs, its frames, its options."""

    #: the ``protocol`` string of bus configs
    name: ClassVar[str]
    #: what the master sends once on a bus after every cycle's frames when a drive of this
    #: protocol is on it (CANopen: SYNC, CiA 301 7.2.5); none by default
    cycle_end_frames: ClassVar[tuple[Frame, ...]] = ()
    #: the error codes (:attr:`hil.hardware.axis.AxisFault.code`) with which its drives say
    #: they lost their master's frames (a watchdog's, CiA 402's RPDO timeout): a stall of the
    #: bench can cause them as it can a silence (hil.control_node.attribution); none by default
    link_loss_codes: ClassVar[frozenset[int]] = frozenset()
    #: the node ids the protocol can address
    node_ids: ClassVar[range] = range(1, 128)
    #: the frames its devices speak; a family that follows the bus declares its
    #: :meth:`bus_frames` classical, and the bus config makes them FD with BRS on an FD bus
    can_fd: ClassVar[CanFd] = CanFd.CLASSIC
    #: a node id with which a drive boots without one, for a master to assign it (CiA 305
    #: LSS: 255); None where the protocol has none
    unconfigured_node_id: ClassVar[int | None] = None
    #: whether its drives fault on a following error (MIT and ODrive firmware do not)
    has_following_error: ClassVar[bool] = True
    #: whether its master can send a torque feed-forward with each setpoint (its axis'
    #: ``cycle_frames`` takes ``torque``): a bus config's ``torque_feed_forward`` needs it
    carries_torque_feed_forward: ClassVar[bool] = False
    #: the protocol's own settings in a bus config: a frozen dataclass, a ProtocolOptions,
    #: with ``KEYS`` and ``from_mapping(values)`` raising ValueError; None if it has none
    Options: ClassVar[type | None] = None
    #: the products its drives can be, by name (``hil init --motor``), each with ``name``,
    #: ``rated_torque``, ``peak_torque`` (N·m), ``no_load_speed`` (rad/s) and
    #: ``reflected_inertia`` (kg·m²) at the drive; none by default
    models: ClassVar[Mapping[str, Any]] = {}
    #: the DriveConfig settings the product keeps in a field of its own (an object, a
    #: register), and that field's range: a bus config's value outside it is refused
    setting_fields: ClassVar[Mapping[str, SettingField]] = {}
    #: "module:Class" of the simulated drive and of the master-side axis
    drive: ClassVar[str]
    axis: ClassVar[str]

    @classmethod
    @abstractmethod
    def bus_frames(cls, node_id: int, cycle_hz: float, heartbeat_period: float, options=None
                   ) -> list[FrameSpec]:
        """Every frame a drive of this protocol and its master use on the bus (rate 0 for
        frames sent only on events). For bus load, ``hil describe`` and identifier
        collisions between drives."""

    @classmethod
    def on_bus(cls, frames: list[FrameSpec], fd: bool) -> list[FrameSpec]:
        """``frames`` (:meth:`bus_frames`) as the family sends them on a bus, FD (``fd``) or
        classical: on an FD bus a family that follows the bus sends FD frames with the bit-rate
        switch (:class:`CanFd`)."""
        if fd and cls.can_fd is CanFd.FOLLOWS_BUS:
            return [replace(frame, fd=True, bitrate_switch=True) for frame in frames]
        return frames

    @classmethod
    def bus_wide_frames(cls, cycle_hz: float) -> list[FrameSpec]:
        """The frames of the bus as a whole once a drive of this protocol is on it, whoever
        they address (CANopen: NMT and SYNC): counted once per bus in its load and owned by
        the protocol in its identifier checks. None by default."""
        return []

    @classmethod
    def description(cls) -> list[str]:
        """What ``hil describe`` prints once for a config with drives of this protocol,
        after its buses (CiA 402: the EDS and its PDO mapping). None by default."""
        return []

    @classmethod
    def torque_feed_forward_frames(cls, node_id: int, cycle_hz: float, options=None
                                   ) -> list[FrameSpec]:
        """The frames a master adds to :meth:`bus_frames` to send a torque feed-forward
        (none where the setpoint's own frame carries one)."""
        return []

    @classmethod
    def frame_source(cls, frame: Frame, drives: Mapping[int, object]) -> FrameSource | None:
        """Who sent a frame seen on a bus whose drives of this protocol are ``drives`` (node
        id -> the drive's options), told by the protocol's ids alone, as a bus monitor tells
        them; None where it is no frame of theirs (another node, another protocol). What a
        replay (:mod:`hil.replay`) feeds to the drives and what it compares. A protocol that
        does not say cannot be replayed."""
        raise NotImplementedError(f"protocol '{cls.name}' does not tell its master's frames "
                                  "from its drives' (Protocol.frame_source)")

    @classmethod
    def source_reads_data(cls, frame: Frame, drives: Mapping[int, object]) -> bool:
        """Whether :meth:`frame_source` of frames like ``frame`` depends on their bytes
        (else its identifier and flags tell it, and a reader may keep the answer)."""
        return True

    @classmethod
    def drive_problem(cls, node_id: int, options=None) -> str | None:
        """What a drive's node id and options miss together (None: nothing), for the bus
        config's reader to report."""
        return None

    @classmethod
    def shared_ids(cls, options=None) -> set[int]:
        """Ids that several drives of this protocol on one bus may use at once."""
        return set()

    @classmethod
    def initial_options(cls, setting: DriveSetting) -> dict | None:
        """The ``options:`` ``hil init`` writes for a drive (None: none)."""
        return None

    @classmethod
    def drive_class(cls) -> type:
        """The simulated drive (imported now)."""
        return load(cls.drive)

    @classmethod
    def axis_class(cls) -> type:
        """The master's side of a drive (imported now)."""
        return load(cls.axis)


def load(reference: str):
    """The object a ``"module:attribute"`` reference names (importing the module)."""
    module, _, attribute = reference.partition(":")
    return getattr(importlib.import_module(module), attribute)
