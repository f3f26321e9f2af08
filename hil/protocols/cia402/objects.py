"""What a simulated CiA 402 drive keeps in its object dictionary: its configuration,
stored into the dictionary at start and at NMT reset; the live objects (statusword,
actual position ...) read by SDO; and SDO writes, checked and applied to the drive's core
and 402 state machine at once (or refused with the CiA 301 abort code)."""

from __future__ import annotations

import math
from collections.abc import Callable
from contextlib import AbstractContextManager
from dataclasses import replace

import canopen
from canopen.sdo import SdoAbortedError
from canopen.sdo.constants import ABORT_INVALID_VALUE, ABORT_VALUE_TOO_LOW

from hil.drives.core import DriveCore
from hil.drives.definitions import SilenceReaction
from hil.protocols.cia402.errors import ErrorRecord
from hil.protocols.cia402.node import DriveNode
from hil.protocols.cia402.personality import Personality
from hil.protocols.cia402.ranges import range_abort
from hil.protocols.cia402.units import SI_UNIT_VELOCITY, velocity_per_rad
from hil.protocols.cia402.storage import ParameterStore
from hil.protocols.cia402.eds import LIVE_OBJECTS
from hil.protocols.cia402.state import (HOMING_METHODS, MODE_CODES, PROFILE_TORQUE,
                                        Cia402StateMachine, int32, live_value, uint32)


class DriveObjects:
    """The object dictionary side of one drive. Every method that touches the core or the
    state machine takes ``lock`` (the drive's, held while the physics steps)."""

    def __init__(self, node: DriveNode, machine: Cia402StateMachine, core: DriveCore,
                 lock: AbstractContextManager, rated_torque: float, heartbeat_ms: int,
                 on_pdo_parameters: Callable[[], None], errors: ErrorRecord,
                 personality: Personality, serial_number: int | None = None,
                 store: ParameterStore | None = None):
        self.node, self.machine, self.core, self.lock = node, machine, core, lock
        self.errors = errors
        self.personality = personality
        #: 0x1018:04 where the bus config gives one (else the EDS's)
        self.serial_number = serial_number
        self.store = store or ParameterStore()
        self.rated_torque = rated_torque
        self.heartbeat_ms = heartbeat_ms
        #: called (under ``lock``) when a PDO's stored communication parameters change
        self.on_pdo_parameters = on_pdo_parameters
        #: user position units per motor radian: increments unless the position factor
        #: (0x6091, 0x6092) says otherwise
        self.counts_per_rad = core.parameters.counts_per_rev / (2 * math.pi)
        #: velocity units per motor rad/s (and acceleration units per rad/s^2): :mod:`.units`
        self.velocity_per_rad = self.counts_per_rad
        node.add_read_callback(self.on_read)
        node.add_write_callback(self.on_write)
        node.on_stored(self.after_store)

    def on_read(self, index: int, subindex: int, od) -> int | None:
        if index in (0x1010, 0x1011) and subindex > 0:
            return 1                 # CiA 301: the device saves (restores) on command
        if index in LIVE_OBJECTS:
            with self.lock:
                return live_value(index, self.machine, self.core.status(),
                                  self.counts_per_rad, self.rated_torque, self.velocity_per_rad)
        return None

    def on_write(self, index: int, subindex: int, od, data: bytes) -> None:
        value = od.decode_raw(data)
        cpr, vpr = self.counts_per_rad, self.velocity_per_rad
        with self.lock:
            if index in (0x1010, 0x1011):
                self.store.command(index, subindex, value, self.node)
            elif index == 0x1003:
                if subindex != 0 or value != 0:
                    raise SdoAbortedError(ABORT_INVALID_VALUE)   # CiA 301: only 0, to clear
                self.errors.history.clear()
                self.store_errors()
            elif index == 0x6040:
                self.machine.controlword(value)
            elif index == 0x6060:
                self.set_mode(value)
            elif index == 0x605A:
                # CiA 402 0-8; hil stops on the quick stop ramp for the current and voltage
                # limits (3, 4, 7, 8) and for 0 (its own reading: the plant has no coasting
                # amplifier to switch off)
                if not 0 <= value <= 8:
                    raise SdoAbortedError(ABORT_INVALID_VALUE)
                self.machine.quick_stop_option = value
            elif index == 0x6007:
                if value not in _SILENCE_REACTIONS:
                    raise SdoAbortedError(ABORT_INVALID_VALUE)
                self.core.silence_reaction = _SILENCE_REACTIONS[value]
            elif index == 0x607A or index == 0x60C1:
                self.set_target_position(index, value)
            elif index == 0x60FF:
                self.core.new_setpoint(velocity=value / vpr)
            elif index == 0x6071:
                self.set_target_torque(value)
            elif index == 0x6088 and value != 0:
                raise SdoAbortedError(ABORT_INVALID_VALUE)       # linear ramps only
            elif index == 0x6087:        # per mille of the rated torque per s (0: a step)
                self.machine.torque_slope = value * self.rated_torque / 1000 or math.inf
            elif index == 0x60B1:
                self.core.new_setpoint(velocity_ff=value / vpr)
            elif index == 0x60B2:
                self.core.new_setpoint(torque_ff=value * self.rated_torque / 1000)
            elif index == 0x607C:
                self.machine.home_offset = value / cpr
            elif index == 0x6099 and subindex in (1, 2):
                setattr(self.machine.homing_speeds, ("switch", "zero")[subindex - 1], value / vpr)
            elif index == 0x609A:
                self.machine.homing_speeds.acceleration = value / vpr
            elif index == 0x6098:
                if value not in HOMING_METHODS and value != 0:     # 0: no homing method
                    raise SdoAbortedError(ABORT_INVALID_VALUE)
                self.machine.homing_method = value
            elif index in (0x6091, 0x6092, 0x6080) and value == 0:
                raise SdoAbortedError(ABORT_VALUE_TOO_LOW)    # a ratio's terms, a top speed
            elif index == 0x60C2:
                self._set_interpolation_period(subindex, value)
            elif index == 0x607D and subindex in (1, 2):
                self._set_position_limits(subindex, value)
            elif index in PROFILE_PARAMETERS:
                self.set_profile_parameter(index, value)
            elif index in _PARAMETER_WRITERS and (self.personality.own or index >= 0x6000):
                self.core.parameters = _PARAMETER_WRITERS[index](
                    self.core.parameters, subindex, value, cpr, vpr)

    def after_store(self, index: int, subindex: int) -> None:
        """A PDO's communication parameters, once stored, take effect: a PDO made valid
        starts with its (checked) mapping, one made not valid stops."""
        if 0x1400 <= index < 0x1600 or 0x1800 <= index < 0x1A00:
            with self.lock:
                self.on_pdo_parameters()
        elif index in (0x6091, 0x6092, SI_UNIT_VELOCITY):
            self.counts_per_rad = self._position_factor()
            self.velocity_per_rad = self._velocity_factor()

    def _position_factor(self) -> float:
        """User units per motor radian: feed constant / gear ratio / 2 pi (CiA 402 6.3.1);
        where the object dictionary has neither, encoder increments."""
        node = self.node
        if 0x6091 not in node.object_dictionary or 0x6092 not in node.object_dictionary:
            return self.core.parameters.counts_per_rev / (2 * math.pi)
        feed = node.value(0x6092, 1) / node.value(0x6092, 2)
        gear = node.value(0x6091, 1) / node.value(0x6091, 2)
        return feed / gear / (2 * math.pi)

    def _velocity_factor(self) -> float:
        """Velocity units per motor rad/s (:mod:`.units`)."""
        node = self.node
        unit = (node.value(SI_UNIT_VELOCITY) if SI_UNIT_VELOCITY in node.object_dictionary
                else None)
        motor, shaft = (node.value(0x6091, 1), node.value(0x6091, 2))
        gear = motor / shaft if motor and shaft else 1.0    # a file without the gear ratio
        return velocity_per_rad(unit, self.counts_per_rad, gear)

    def set_mode(self, code: int) -> None:
        """0x6060: a mode the drive offers (its personality's 0x6502); 0 ("no mode",
        a vendor file's usual default) leaves the mode as it is."""
        if code == 0:
            return
        if code not in self.personality.modes:
            raise SdoAbortedError(ABORT_INVALID_VALUE)   # value range of parameter exceeded
        self.machine.mode_code = code
        self.core.set_mode(MODE_CODES[code])

    def set_target_position(self, index: int, counts: int) -> None:
        """0x607A (profile and cyclic synchronous position) or 0x60C1:01 (interpolated
        position: taken while ip mode is active)."""
        self.machine.take_target_position(index, counts / self.counts_per_rad)

    def set_target_torque(self, value: int) -> None:
        """0x6071 (per mille of the rated torque): cyclic synchronous torque's setpoint, or
        profile torque's target (reached on its slope)."""
        torque = value * self.rated_torque / 1000
        if self.machine.mode_code == PROFILE_TORQUE:
            self.machine.torque_target = torque
        else:
            self.core.new_setpoint(torque=torque)

    def set_profile_parameter(self, index: int, value: int) -> None:
        """A profile velocity, acceleration or deceleration, by SDO (checked before, as every
        write: :mod:`.ranges`) or from an RPDO. An RPDO's value the object does not take (a
        rate of 0, one outside the file's limits) is not taken: the one before stays, as
        CANopenNode drops a PDO's write its object dictionary refuses (CiA 301 gives a PDO
        no answer to refuse it with)."""
        entry = self.node.object_dictionary[index]
        if range_abort(entry, entry.encode_raw(value)) is not None:
            return
        self.core.parameters = replace(self.core.parameters, **{
            PROFILE_PARAMETERS[index]: value / self.velocity_per_rad})

    def _set_interpolation_period(self, subindex: int, value: int) -> None:
        """0x60C2: the CSP interpolation period is value x 10^index s. What the object takes
        is its file's (hil's own EDS: value 1-255, index -6..0; CiA 402 gives a vendor's
        the types' whole range, checked before: :mod:`.ranges`); a period hil cannot time
        (0, or an index outside -6..0 that a vendor's file allows) is stored and the drive
        keeps the period it has (hil's reading: CiA 402 gives 0 no meaning)."""
        period = self.node.value(0x60C2, 1)
        exponent = self.node.value(0x60C2, 2)
        if subindex == 1:
            period = value
        elif subindex == 2:
            exponent = value
        if period > 0 and -6 <= exponent <= 0:
            self.core.set_cycle(period * 10.0 ** exponent)

    def _set_position_limits(self, subindex: int, value: int) -> None:
        """0x607D: min (1) and max (2) position limit, in position units. Both 0: no limits,
        as the makers document it (Novanta/Ingenia EMCL and Summit manuals, 0x607D: "to
        disable the software position limits, the min position limit and max position limit
        shall be set to 0"; Kollmorgen AKD: default 0, "switched off"); CiA 402 itself
        names no such value, and a window of zero width is no position a drive can hold."""
        limits = [self.node.value(0x607D, 1), self.node.value(0x607D, 2)]
        limits[subindex - 1] = value
        low, high = (bound / self.counts_per_rad for bound in limits)
        self.core.parameters = replace(self.core.parameters, position_limits=(
            None if limits == [0, 0] else (low, high)))

    def store_configuration(self) -> None:
        """Write the drive's configured values into its object dictionary (in increments:
        the position factor takes its defaults)."""
        p = self.core.parameters
        self.counts_per_rad = p.counts_per_rev / (2 * math.pi)
        cpr = self.counts_per_rad
        put = self._put
        self.store_communication()
        put(0x6091, 1, 1)
        put(0x6091, 2, 1)
        put(0x6092, 1, p.counts_per_rev)
        put(0x6092, 2, 1)
        vpr = self.velocity_per_rad = self._velocity_factor()
        put(0x6076, None, round(self.rated_torque * 1000))
        put(0x6072, None, round(p.peak_torque / self.rated_torque * 1000))
        put(0x608F, 1, p.counts_per_rev)
        put(0x607F, None, uint32(p.max_velocity * vpr))
        # 0x6080 in the velocity unit of the other objects (:mod:`.units`: 0x60A9 where the
        # file has it, rpm for many makers)
        put(0x6080, None, uint32(p.max_velocity * vpr))
        put(0x6081, None, uint32(p.profile_velocity * vpr))
        put(0x6083, None, uint32(p.profile_acceleration * vpr))
        put(0x6084, None, uint32(p.profile_deceleration * vpr))
        put(0x6085, None, uint32(p.quick_stop_deceleration * vpr))
        # homing at the profile's speed (searching for a switch), a quarter of it (for the
        # index pulse) and its acceleration: hil's defaults, CiA 402 names none
        speeds = self.machine.homing_speeds
        speeds.switch, speeds.zero = p.profile_velocity, p.profile_velocity / 4
        speeds.acceleration = p.profile_acceleration
        put(0x6099, 1, uint32(speeds.switch * vpr))
        put(0x6099, 2, uint32(speeds.zero * vpr))
        put(0x609A, None, uint32(speeds.acceleration * vpr))
        window = p.following_error_limit
        put(0x6065, None, min(uint32(window * cpr), FOLLOWING_OFF - 1) if window > 0
            else FOLLOWING_OFF)
        put(0x6066, None, round(p.following_error_timeout * 1000))
        put(0x6007, None, self.core.silence_reaction.value)
        if self.personality.own:
            put(0x2010, None, round(p.watchdog_timeout * 1000))
            put(0x2000, 1, p.position_kp)
            put(0x2000, 2, p.velocity_kp)
            put(0x2000, 3, p.velocity_ki)
        value, exponent = interpolation_period(self.core.cycle)
        put(0x60C2, 1, value)
        put(0x60C2, 2, exponent)
        if p.position_limits is not None:
            put(0x607D, 1, int32(p.position_limits[0] * cpr))
            put(0x607D, 2, int32(p.position_limits[1] * cpr))

    def store_communication(self) -> None:
        self._put(0x1017, None, self.heartbeat_ms)
        if self.serial_number is not None:
            self._put(0x1018, 4, self.serial_number)
        self.store_errors()

    def store_errors(self) -> None:
        """0x1003 as the error record has it (its count, then the newest first)."""
        self._put(0x1003, 0, len(self.errors.history))
        for subindex, entry in enumerate(self.errors.fields(), start=1):
            self._put(0x1003, subindex, entry)

    def _put(self, index: int, subindex: int | None, value) -> None:
        """Store a value, where the object dictionary (a vendor's may not) has the object."""
        entry = self.node.object_dictionary.get(index)
        if subindex is not None and entry is not None:
            entry = (entry.subindices.get(subindex)
                     if not isinstance(entry, canopen.objectdictionary.ODVariable) else None)
        if entry is None:
            return
        self.node.data_store.setdefault(index, {})[subindex or 0] = entry.encode_raw(value)


def interpolation_period(cycle: float) -> tuple[int, int]:
    """0x60C2's (value, index) for a period in s: the coarsest exponent that represents it
    in a byte, to the microsecond."""
    for exponent in (-3, -4, -5, -6):
        value = cycle / 10.0 ** exponent
        if abs(value - round(value)) < 1e-6 * value and 1 <= round(value) <= 255:
            return round(value), exponent
    return max(1, min(255, round(cycle * 1e4))), -4


def _following_window(p, subindex, value, cpr, vpr):
    """CiA 402 0x6065: FFFFFFFFh switches the following control off (hil's limit 0, which
    the drive's core reads as off); 0 is a window of no width, not off: an error of half an
    increment (one the encoder reads) faults after the time out 0x6066."""
    if value == FOLLOWING_OFF:
        return replace(p, following_error_limit=0.0)
    return replace(p, following_error_limit=max(value, 0.5) / cpr)


def _gains(p, subindex, value, cpr, vpr):
    name = {1: "position_kp", 2: "velocity_kp", 3: "velocity_ki"}.get(subindex)
    return replace(p, **{name: float(value)}) if name else p


#: SDO-writable parameters that take effect at once: index -> (parameters, sub, value,
#: position units/rad, velocity units per rad/s)
_PARAMETER_WRITERS = {
    0x2000: _gains,
    0x2010: lambda p, s, v, c, vc: replace(p, watchdog_timeout=v / 1000),
    0x6065: _following_window,
    0x6066: lambda p, s, v, c, vc: replace(p, following_error_timeout=v / 1000),
    0x6085: lambda p, s, v, c, vc: replace(p, quick_stop_deceleration=v / vc),
    0x6080: lambda p, s, v, c, vc: replace(p, max_velocity=v / vc),
}
#: 0x6065's value for "following control switched off" (CiA 402)
FOLLOWING_OFF = 0xFFFFFFFF
#: profile-mode objects (increments/s, /s^2) -> DriveParameters field (rad/s, /s^2)
PROFILE_PARAMETERS = {0x6081: "profile_velocity", 0x6083: "profile_acceleration",
                       0x6084: "profile_deceleration"}
#: 0x6007 values this drive takes (manufacturer-specific negative ones it has none of)
_SILENCE_REACTIONS = {reaction.value: reaction for reaction in SilenceReaction}
