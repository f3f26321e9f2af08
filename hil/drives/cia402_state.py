"""The CiA 402 device side without CAN: power state machine, statusword, live objects.

What a 402 drive computes from its :class:`DriveCore` at every controlword and SYNC; the
profile (:mod:`hil.drives.cia402`) carries it over canopen. Typed Python that the install
compiles with mypyc together with the core (``setup.py``): it runs for every drive on every
cycle.
"""

from __future__ import annotations

import enum

from hil.drives.core import DriveCore, DriveStatus, Fault, Mode, Power

#: CiA 402 modes of operation (0x6060/0x6061) this drive supports.
MODE_CODES = {8: Mode.POSITION, 9: Mode.VELOCITY, 10: Mode.TORQUE}
CODE_OF_MODE = {mode: code for code, mode in MODE_CODES.items()}

#: error register (0x1001) of each fault; bits (CiA 301): 0x01 generic, 0x10 communication,
#: 0x20 device profile, 0x80 manufacturer
ERROR_REGISTER = {Fault.FOLLOWING_ERROR: 0x21, Fault.POSITION_LIMIT: 0x21,
                  Fault.CONTROLLER_SILENT: 0x11, Fault.EMERGENCY_STOP: 0x81}

#: objects read from the drive's state, not stored in its object dictionary
LIVE_OBJECTS = frozenset({0x6041, 0x6061, 0x6064, 0x606C, 0x6077, 0x60F4, 0x603F, 0x1001})


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
        self.quick_stop_option = quick_stop_option
        self._disabled_state = State.SWITCH_ON_DISABLED
        self._last_controlword = 0

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
        """Apply one controlword (CiA 402 transitions 2-12, 15, 16)."""
        rising_reset = bool(word & 0x80) and not self._last_controlword & 0x80
        self._last_controlword = word
        state = self.state
        if state is State.FAULT:
            if rising_reset:
                self.core.reset_fault()
                self._disabled_state = State.SWITCH_ON_DISABLED
            return
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

    def after_update(self) -> None:
        """Quick stop option 1-4: once stopped, fall to switch on disabled."""
        if (self.core.power is Power.QUICK_STOP and self.quick_stop_option < 5
                and self.core.status().stopped):
            self._to_disabled(State.SWITCH_ON_DISABLED)

    def _to_disabled(self, state: State) -> None:
        self.core.disable()
        self._disabled_state = state


def statusword(state: State, status: DriveStatus) -> int:
    """0x6041 for a state and the core's flags."""
    word = state.value | 0x0200                                   # bit 9: remote
    if state in (State.READY_TO_SWITCH_ON, State.SWITCHED_ON, State.OPERATION_ENABLED,
                 State.QUICK_STOP_ACTIVE):
        word |= 0x0010                                            # bit 4: voltage enabled
    if status.target_reached:
        word |= 0x0400
    if status.internal_limit:
        word |= 0x0800
    if state is State.OPERATION_ENABLED and status.mode is not Mode.TORQUE:
        word |= 0x1000                                            # bit 12: following targets
    if status.following_error_exceeded and status.mode is Mode.POSITION:
        word |= 0x2000
    return word


def live_value(index: int, state: State, status: DriveStatus, counts_per_rad: float,
               rated_torque: float) -> int:
    """The value of live object ``index`` (one of :data:`LIVE_OBJECTS`)."""
    if index == 0x6041:
        return statusword(state, status)
    if index == 0x6064:
        return int32(status.position * counts_per_rad)
    if index == 0x606C:
        return int32(status.velocity * counts_per_rad)
    if index == 0x6077:
        return int16(status.torque / rated_torque * 1000)
    if index == 0x60F4:
        return int32(status.following_error * counts_per_rad)
    if index == 0x6061:
        return CODE_OF_MODE[status.mode]
    fault = status.fault
    if index == 0x603F:
        return fault.code if fault is not None else 0
    if index == 0x1001:
        return ERROR_REGISTER[fault] if fault is not None else 0
    raise KeyError(f"0x{index:04X} is not a live object")


def live_values(indices: tuple[int, ...], state: State, status: DriveStatus,
                counts_per_rad: float, rated_torque: float) -> list[int]:
    """The values of a PDO's live objects, in its mapping's order."""
    return [live_value(index, state, status, counts_per_rad, rated_torque)
            for index in indices]


# saturating conversions to the objects' integer types (a value out of range is clamped, as
# a drive's firmware would, never wrapped)
def int32(value: float) -> int:
    return max(-2**31, min(2**31 - 1, round(value)))


def uint32(value: float) -> int:
    return max(0, min(2**32 - 1, round(value)))


def int16(value: float) -> int:
    return max(-2**15, min(2**15 - 1, round(value)))
