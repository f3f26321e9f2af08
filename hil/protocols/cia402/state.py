"""The CiA 402 device side without CAN: power state machine, statusword, live objects.

What a 402 drive computes from its :class:`DriveCore` at every controlword and SYNC; the
drive (:mod:`hil.protocols.cia402.drive`) carries it over canopen. Typed Python that the install
compiles with mypyc together with the core (``setup.py``): it runs for every drive on every
cycle.
"""

from __future__ import annotations

import enum
import math

from hil.drives.core import DriveCore
from hil.drives.definitions import DriveStatus, Fault, Mode, Power, round_half_even
from hil.protocols.cia402 import (EMCY_EMERGENCY_STOP, EMCY_FOLLOWING_ERROR,
                                  EMCY_HEARTBEAT_LOST, EMCY_POSITION_LIMIT, EMCY_RPDO_TIMEOUT)
from hil.protocols.cia402.homing import METHODS, Homing, HomingSpeeds

#: CiA 402 modes of operation (0x6060/0x6061) this drive supports: profile position (1),
#: profile velocity (3), profile torque (4), homing (6), interpolated position (7: the position of each SYNC's
#: interpolation data record 0x60C1:01, followed as in CSP while controlword bit 4 "enable ip
#: mode" is set), cyclic synchronous position/velocity/torque (8, 9, 10)
MODE_CODES = {1: Mode.PROFILE_POSITION, 3: Mode.PROFILE_VELOCITY, 4: Mode.TORQUE,
              6: Mode.HOMING, 7: Mode.POSITION, 8: Mode.POSITION, 9: Mode.VELOCITY,
              10: Mode.TORQUE}
#: the modes that share a core mode with a cyclic one: profile torque (4: the target torque
#: 0x6071 reached on the torque slope 0x6087, halt ramps it to 0) and interpolated position
PROFILE_TORQUE, INTERPOLATED_POSITION = 4, 7
CODE_OF_MODE = {mode: code for code, mode in MODE_CODES.items()
                if code not in (PROFILE_TORQUE, INTERPOLATED_POSITION)}
#: 0x6502, supported drive modes: bit (code - 1) of each mode above
SUPPORTED_MODES = sum(1 << (code - 1) for code in MODE_CODES)
#: homing methods (0x6098) this drive runs (:mod:`.homing`)
HOMING_METHODS = METHODS

#: error register (0x1001) of each fault; bits (CiA 301): 0x01 generic, 0x10 communication,
#: 0x20 device profile, 0x80 manufacturer
ERROR_REGISTER = {Fault.FOLLOWING_ERROR: 0x21, Fault.POSITION_LIMIT: 0x21,
                  Fault.CONTROLLER_SILENT: 0x11, Fault.HEARTBEAT_LOST: 0x11,
                  Fault.EMERGENCY_STOP: 0x81}
#: the EMCY error code (and 0x603F's) of each fault (CiA 301 table 21, CiA 402)
EMCY_CODES = {Fault.FOLLOWING_ERROR: EMCY_FOLLOWING_ERROR,
              Fault.POSITION_LIMIT: EMCY_POSITION_LIMIT,
              Fault.CONTROLLER_SILENT: EMCY_RPDO_TIMEOUT,
              Fault.HEARTBEAT_LOST: EMCY_HEARTBEAT_LOST,
              Fault.EMERGENCY_STOP: EMCY_EMERGENCY_STOP}

# controlword bits of the operation modes (CiA 402): profile position's new set-point,
# change set immediately and relative target; homing's start (the same bit 4); halt
NEW_SETPOINT, CHANGE_IMMEDIATELY, RELATIVE, HALT = 0x0010, 0x0020, 0x0040, 0x0100
#: interpolated position mode's controlword bit 4 (the new set-point bit of profile position)
ENABLE_IP = 0x0010



class State(enum.Enum):
    """The CiA 402 power states, with their statusword value (mask 0x6F)."""

    NOT_READY_TO_SWITCH_ON = 0x00
    SWITCH_ON_DISABLED = 0x40
    READY_TO_SWITCH_ON = 0x21
    SWITCHED_ON = 0x23
    OPERATION_ENABLED = 0x27
    QUICK_STOP_ACTIVE = 0x07
    FAULT_REACTION_ACTIVE = 0x0F
    FAULT = 0x08


class Cia402StateMachine:
    """The 402 power state machine driven by controlword 0x6040.

    The drive core owns whether power is on; this class holds the disabled
    sub-states (switch on disabled / ready to switch on / switched on) and
    translates controlword commands into core calls.
    """

    def __init__(self, core: DriveCore, quick_stop_option: int = 6):
        self.core = core
        #: 0x1001, kept by the drive's error record (hil.protocols.cia402.errors)
        self.error_register = 0
        self.quick_stop_option = quick_stop_option
        self._disabled_state = State.SWITCH_ON_DISABLED
        self._last_controlword = 0
        #: profile position: target position 0x607A (rad, motor), read at each new set-point
        self.target_position = 0.0
        #: homing: home offset 0x607C (rad, motor): the position where homing leaves the axis
        self.home_offset = 0.0
        self.homing_method = 35
        self.homing_speeds = HomingSpeeds()
        self._homing: Homing | None = None      # a homing run in progress
        #: 0x6060 as last set (0: none yet): interpolated position shares CSP's core mode
        self.mode_code = 0
        #: profile torque: the target 0x6071, the slope 0x6087 (N·m, N·m/s; inf: a step)
        #: and the torque demand the ramp has reached
        self.torque_target = 0.0
        self.torque_slope = math.inf
        self.torque_demand = 0.0
        self.setpoint_acknowledged = False
        self._buffered: float | None = None     # profile position: the next set-point
        self._last_target = 0.0                 # profile position: the latest set-point taken
        self.homing_attained = False
        self.homing_error = False
        self._last_power = core.power           # as of the last command or update

    @property
    def state(self) -> State:
        power = self.core.power
        if power is Power.FAULT:
            return State.FAULT
        if power is Power.QUICK_STOP:
            return State.QUICK_STOP_ACTIVE
        if power is Power.ENABLED:
            return State.OPERATION_ENABLED
        return self._disabled_state

    def controlword(self, word: int) -> None:
        """Apply one controlword (CiA 402 transitions 2-12, 15, 16, then the operation mode's
        bits: new set-point, change immediately, relative, homing start, halt)."""
        previous = self._last_controlword
        rising_reset = bool(word & 0x80) and not previous & 0x80
        self._last_controlword = word
        state = self.state
        if state is State.FAULT:
            if rising_reset:
                self.core.reset_fault()
                self._disabled_state = State.SWITCH_ON_DISABLED
            return
        self._power_transition(word, state)
        self._operation(word, previous)
        self._last_power = self.core.power

    def _power_transition(self, word: int, state: State) -> None:
        if word & 0x82 == 0x00:                                   # disable voltage
            self._to_disabled(State.SWITCH_ON_DISABLED)
        elif word & 0x86 == 0x02:                                 # quick stop
            if state is State.OPERATION_ENABLED:
                self.core.quick_stop()
            elif state is not State.QUICK_STOP_ACTIVE:
                self._to_disabled(State.SWITCH_ON_DISABLED)
        elif word & 0x87 == 0x06:                                 # shutdown
            if state is not State.QUICK_STOP_ACTIVE:
                self._to_disabled(State.READY_TO_SWITCH_ON)
        elif word & 0x8F == 0x07:                                 # switch on / disable op.
            if state in (State.READY_TO_SWITCH_ON, State.OPERATION_ENABLED):
                self._to_disabled(State.SWITCHED_ON)
        elif word & 0x8F == 0x0F:                                 # enable operation
            if state in (State.READY_TO_SWITCH_ON, State.SWITCHED_ON) or (
                    state is State.QUICK_STOP_ACTIVE and self.quick_stop_option >= 5):
                self.core.enable()

    def _operation(self, word: int, previous: int) -> None:
        """The operation mode's controlword bits, while operation is enabled."""
        core = self.core
        if core.power is not Power.ENABLED:
            self.setpoint_acknowledged = False
            self._buffered = None
            return
        mode = core.mode
        rising = bool(word & NEW_SETPOINT) and not previous & NEW_SETPOINT
        if mode is Mode.PROFILE_POSITION or mode is Mode.PROFILE_VELOCITY:
            core.halt(bool(word & HALT))
        if mode is Mode.PROFILE_POSITION:
            if rising and not self.setpoint_acknowledged:
                target = self.target_position
                if word & RELATIVE:
                    target += self._last_target
                self._last_target = target
                if word & CHANGE_IMMEDIATELY or core.move_done:
                    core.move_to(target)
                else:
                    self._buffered = target          # taken when the move in progress ends
                self.setpoint_acknowledged = True
            elif not word & NEW_SETPOINT and self._buffered is None:
                self.setpoint_acknowledged = False
        elif mode is Mode.HOMING and rising:
            self._home()

    def _home(self) -> None:
        """Homing start: a run of the method's moves (:mod:`.homing`)."""
        self._stop_homing()
        self.homing_attained = False
        run = (Homing(self.core, self.homing_method, self.homing_speeds)
               if self.homing_method in HOMING_METHODS else None)
        self.homing_error = run is None or run.failed
        if not self.homing_error:
            self._homing = run
            self._advance_homing()

    def _advance_homing(self) -> None:
        run = self._homing
        if run is not None and run.advance():
            self._homing = None
            # the home position reads the home offset (CiA 402); the axis holds there
            self.core.rebase(self.home_offset - self.core.status().position)
            self.core.hold_position()
            self.homing_attained = True

    def _stop_homing(self) -> None:
        if self._homing is not None:
            self._homing.abandon()
            self._homing = None

    def mode_bits(self, status: DriveStatus) -> int:
        """Statusword bits 12 and 13 of the operation mode in force."""
        mode = status.mode
        if mode is Mode.PROFILE_POSITION:
            return ((0x1000 if self.setpoint_acknowledged else 0)
                    | (0x2000 if status.following_error_exceeded else 0))
        if mode is Mode.PROFILE_VELOCITY:
            still = abs(status.velocity) < 0.01 * self.core.parameters.max_velocity
            return 0x1000 if still else 0                    # bit 12: speed is 0
        if mode is Mode.HOMING:
            return ((0x1000 if self.homing_attained else 0)
                    | (0x2000 if self.homing_error else 0))
        if self.mode_code == PROFILE_TORQUE or self.state is not State.OPERATION_ENABLED:
            return 0                # (bits 12 and 13 are reserved in profile torque)
            return 0
        if not self.following_setpoints():
            return 0               # interpolated position, bit 4 clear: ip mode not active
        bits = 0x1000              # bit 12 in CSP, CSV and CST: the drive follows the target
        # (in interpolated position: ip mode active)
        if status.following_error_exceeded and mode is Mode.POSITION:
            bits |= 0x2000
        return bits

    def ramp_torque(self, dt: float) -> None:
        """Profile torque: the demand ``dt`` further toward the target (0 while halted) at
        the torque slope (linear, 0x6088 = 0)."""
        if self.mode_code != PROFILE_TORQUE or self.core.power is not Power.ENABLED:
            self.torque_demand = 0.0
            return
        goal = self._torque_goal()
        step = self.torque_slope * dt
        if abs(goal - self.torque_demand) <= step:
            self.torque_demand = goal
        else:
            self.torque_demand += step if goal > self.torque_demand else -step
        self.core.new_setpoint(torque=self.torque_demand)

    def _torque_goal(self) -> float:
        return 0.0 if self._last_controlword & HALT else self.torque_target

    def torque_reached(self) -> bool:
        """Profile torque's statusword bit 10: the demand is at the target (0 halted)."""
        return self.torque_demand == self._torque_goal()

    def following_setpoints(self) -> bool:
        """Whether cyclic setpoints are taken: always, but in interpolated position mode
        only while controlword bit 4 is set (CiA 402 "enable ip mode")."""
        return (self.mode_code != INTERPOLATED_POSITION
                or bool(self._last_controlword & ENABLE_IP))

    def take_target_position(self, index: int, position: float) -> None:
        """0x607A (profile and cyclic synchronous position) or 0x60C1:01 (interpolated
        position: taken while ip mode is active), in rad at the motor. Here, compiled, and
        not in the drive's interpreted objects: each access of theirs to this machine's
        attributes would be a generic lookup, at every RPDO."""
        interpolated = self.mode_code == INTERPOLATED_POSITION
        if (index == 0x60C1) != interpolated:
            if index == 0x607A:
                self.target_position = position
            return
        if interpolated and not self.following_setpoints():
            return
        self.target_position = position
        self.core.new_setpoint(position=position)

    def after_update(self) -> bool:
        """Quick stop option 1-4: once stopped, fall to switch on disabled. A drive that
        disabled itself (a silence reaction, 0x6007 = 2) is in switch on disabled too.
        Profile position: a buffered set-point starts once the move in progress has ended.
        Returns whether the core has faults not yet taken (its ``events``): asked here, in
        compiled code, the drive's interpreted caller reads no attribute of the core at
        every plant step."""
        power = self.core.power
        if power is Power.DISABLED and self._last_power in (Power.ENABLED, Power.QUICK_STOP):
            self._disabled_state = State.SWITCH_ON_DISABLED
        self._last_power = power
        if (power is Power.QUICK_STOP and self.quick_stop_option < 5
                and self.core.status().stopped):
            self._to_disabled(State.SWITCH_ON_DISABLED)
        if self._homing is not None:
            if (power is not Power.ENABLED or self.core.mode is not Mode.HOMING
                    or self._last_controlword & HALT):
                self._stop_homing()          # interrupted: neither attained nor an error
            else:
                self._advance_homing()
        if self._buffered is not None and self.core.move_done:
            self.core.move_to(self._buffered)
            self._buffered = None
            if not self._last_controlword & NEW_SETPOINT:
                self.setpoint_acknowledged = False
        return bool(self.core.events)

    def reset_homing(self) -> None:
        """A node reset: the drive forgets its home (its position scale is the encoder's)."""
        self._stop_homing()
        self.core.rebase(-self.core.offset)
        self.homing_attained = self.homing_error = False

    def _to_disabled(self, state: State) -> None:
        self.core.disable()
        self._disabled_state = state
        self._last_power = self.core.power


def statusword(state: State, status: DriveStatus, mode_bits: int) -> int:
    """0x6041 for a state, the core's flags and the operation mode's bits 12-13."""
    # _value_, not value: the latter is a Python property, two calls at every statusword
    # (every TPDO of every drive); a dict by state would hash it in Python
    word = state._value_ | 0x0200 | mode_bits                     # bit 9: remote
    if state in (State.READY_TO_SWITCH_ON, State.SWITCHED_ON, State.OPERATION_ENABLED,
                 State.QUICK_STOP_ACTIVE):
        word |= 0x0010                                            # bit 4: voltage enabled
    if status.target_reached:
        word |= 0x0400
    if status.internal_limit:
        word |= 0x0800
    return word


def live_value(index: int, machine: Cia402StateMachine, status: DriveStatus,
               counts_per_rad: float, rated_torque: float,
               velocity_per_rad: float | None = None) -> int:
    """The value of live object ``index`` (one of :data:`LIVE_OBJECTS`); positions in
    ``counts_per_rad`` units, velocities in ``velocity_per_rad`` (by default the same: per
    second), as the drive's units have them (:mod:`hil.protocols.cia402.units`)."""
    if index == 0x6041:
        word = statusword(machine.state, status, machine.mode_bits(status))
        if machine.mode_code == PROFILE_TORQUE and status.mode is Mode.TORQUE:
            reached = machine.torque_reached() and status.power is Power.ENABLED
            word = (word & ~0x0400) | (0x0400 if reached else 0)     # bit 10: the torque's
        return word
    if index == 0x6064:
        return int32(status.position * counts_per_rad)
    if index == 0x606C:
        return int32(status.velocity * (velocity_per_rad or counts_per_rad))
    if index == 0x6077:
        return int16(status.torque / rated_torque * 1000)
    if index == 0x60F4:
        return int32(status.following_error * counts_per_rad)
    if index == 0x6061:
        if MODE_CODES.get(machine.mode_code) is status.mode:
            return machine.mode_code
        return CODE_OF_MODE[status.mode]
    fault = status.fault
    if index == 0x603F:
        return EMCY_CODES[fault] if fault is not None else 0
    if index == 0x1001:
        return machine.error_register
    raise KeyError(f"0x{index:04X} is not a live object")


def live_values(indices: tuple[int, ...], machine: Cia402StateMachine, status: DriveStatus,
                counts_per_rad: float, rated_torque: float,
                velocity_per_rad: float | None = None) -> list[int]:
    """The values of a PDO's live objects, in its mapping's order."""
    return [live_value(index, machine, status, counts_per_rad, rated_torque, velocity_per_rad)
            for index in indices]


# saturating conversions to the objects' integer types: a value out of range is clamped, as
# a drive's firmware would, never wrapped. Compared, not max(min()), and round_half_even, not
# round(): builtins called from compiled code go through Python (a TPDO's every value comes
# through here)
def int32(value: float) -> int:
    return _clamped(round_half_even(value), -2**31, 2**31 - 1)


def uint32(value: float) -> int:
    return _clamped(round_half_even(value), 0, 2**32 - 1)


def int16(value: float) -> int:
    return _clamped(round_half_even(value), -2**15, 2**15 - 1)


def _clamped(value: int, lowest: int, highest: int) -> int:
    return lowest if value < lowest else highest if value > highest else value
