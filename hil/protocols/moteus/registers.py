"""moteus' registers: their numbers, what each measures and how an integer carries it.

Sources: mjbots' register reference (github.com/mjbots/moteus, docs/protocol/registers.md,
"Mappings" and "Registers") and the firmware that serves them (fw/moteus_controller.cc:
``ScaleMapping`` and ``ReadScaleMapping``, the ``Register`` enumeration, ``Write`` and
``Read``). A register read as int8, int16 or int32 carries ``value / LSB`` truncated toward
zero and limited to +-the type's maximum (the maximally negative integer is NaN, both ways:
``ScaleSaturate``, ``ValueScaler``); as float, the value itself. Mode, fault and the other
integer registers are carried as they are (``IntMapping``).
"""

from __future__ import annotations

import enum
import math
import struct
from dataclasses import dataclass

#: the value types of a subframe, by the two bits that name them (docs/protocol/can.md,
#: "Subframes": 0x00 int8, 0x04 int16, 0x08 int32, 0x0c float)
INT8, INT16, INT32, FLOAT = range(4)
TYPES = (struct.Struct("<b"), struct.Struct("<h"), struct.Struct("<i"), struct.Struct("<f"))
#: the largest integer of each integral type; its negative minus one is NaN
LIMITS = (127, 32767, 2147483647)


class Mode(enum.IntEnum):
    """Register 0x000 (registers.md "0x000 - Mode"; fw/bldc_servo_structs.h BldcServoMode)."""

    STOPPED = 0
    FAULT = 1
    ENABLING = 2
    CALIBRATING = 3
    CALIBRATION_COMPLETE = 4
    PWM = 5
    VOLTAGE = 6
    VOLTAGE_FOC = 7
    VOLTAGE_DQ = 8
    CURRENT = 9
    POSITION = 10
    #: entered by the watchdog from position mode; left only by a stop
    POSITION_TIMEOUT = 11
    ZERO_VELOCITY = 12
    STAY_WITHIN = 13
    MEASURE_INDUCTANCE = 14
    BRAKE = 15


#: the fault codes of register 0x00f (registers.md "0x00f - Fault code"; fw/error.h)
FAULTS = {32: "calibration fault", 33: "motor driver fault", 34: "over voltage",
          35: "encoder fault", 36: "motor not configured", 37: "pwm cycle overrun",
          38: "over temperature", 39: "outside limit", 40: "under voltage",
          41: "config changed", 42: "theta invalid", 43: "position invalid",
          44: "driver enable fault", 45: "stop position deprecated", 46: "timing violation",
          47: "bemf feedforward no accel", 48: "invalid limits",
          49: "position control error", 50: "velocity control error"}


@dataclass(frozen=True)
class Scale:
    """One LSB of each integral type (registers.md "Mappings"); None: carried as an
    integer (``IntMapping``)."""

    lsb: tuple[float, float, float] | None


INTEGER = Scale(None)
POSITION = Scale((0.01, 0.0001, 0.00001))             # revolutions
VELOCITY = Scale((0.1, 0.00025, 0.00001))             # Hz
ACCELERATION = Scale((0.05, 0.001, 0.00001))          # revolutions/s²
TORQUE = Scale((0.5, 0.01, 0.001))                    # N·m
CURRENT = Scale((1.0, 0.1, 0.001))                    # A
TEMPERATURE = Scale((1.0, 0.1, 0.001))                # °C
VOLTAGE = Scale((0.5, 0.1, 0.001))                    # V
TIME = Scale((0.01, 0.001, 0.000001))                 # s
PWM = Scale((1 / 127, 1 / 32767, 1 / 2147483647))     # unitless: PWM, kp and kd scales
POWER = Scale((10.0, 0.05, 0.0001))                   # W


class Register(enum.IntEnum):
    """The registers hil's moteus serves (registers.md; fw/moteus_controller.cc)."""

    MODE = 0x000
    POSITION = 0x001
    VELOCITY = 0x002
    TORQUE = 0x003
    Q_CURRENT = 0x004
    D_CURRENT = 0x005
    POWER = 0x007
    MOTOR_TEMPERATURE = 0x00A
    TRAJECTORY_COMPLETE = 0x00B
    HOME_STATE = 0x00C
    VOLTAGE = 0x00D
    TEMPERATURE = 0x00E
    FAULT = 0x00F
    COMMAND_POSITION = 0x020
    COMMAND_VELOCITY = 0x021
    FEEDFORWARD_TORQUE = 0x022
    KP_SCALE = 0x023
    KD_SCALE = 0x024
    MAXIMUM_TORQUE = 0x025
    STOP_POSITION = 0x026
    WATCHDOG_TIMEOUT = 0x027
    VELOCITY_LIMIT = 0x028
    ACCEL_LIMIT = 0x029
    FIXED_VOLTAGE_OVERRIDE = 0x02A
    ILIMIT_SCALE = 0x02B
    FIXED_CURRENT_OVERRIDE = 0x02C
    IGNORE_POSITION_BOUNDS = 0x02D
    CONTROL_POSITION = 0x038
    CONTROL_VELOCITY = 0x039
    CONTROL_TORQUE = 0x03A
    POSITION_ERROR = 0x03B
    VELOCITY_ERROR = 0x03C
    MILLISECOND_COUNTER = 0x070
    REGISTER_MAP_VERSION = 0x102
    SET_OUTPUT_NEAREST = 0x130
    SET_OUTPUT_EXACT = 0x131


#: the scale of every register hil serves
SCALES = {
    Register.MODE: INTEGER, Register.POSITION: POSITION, Register.VELOCITY: VELOCITY,
    Register.TORQUE: TORQUE, Register.Q_CURRENT: CURRENT, Register.D_CURRENT: CURRENT,
    Register.POWER: POWER, Register.MOTOR_TEMPERATURE: TEMPERATURE,
    Register.TRAJECTORY_COMPLETE: INTEGER, Register.HOME_STATE: INTEGER,
    Register.VOLTAGE: VOLTAGE, Register.TEMPERATURE: TEMPERATURE, Register.FAULT: INTEGER,
    Register.COMMAND_POSITION: POSITION, Register.COMMAND_VELOCITY: VELOCITY,
    Register.FEEDFORWARD_TORQUE: TORQUE, Register.KP_SCALE: PWM, Register.KD_SCALE: PWM,
    Register.MAXIMUM_TORQUE: TORQUE, Register.STOP_POSITION: POSITION,
    Register.WATCHDOG_TIMEOUT: TIME, Register.VELOCITY_LIMIT: VELOCITY,
    Register.ACCEL_LIMIT: ACCELERATION, Register.FIXED_VOLTAGE_OVERRIDE: VOLTAGE,
    Register.ILIMIT_SCALE: PWM, Register.FIXED_CURRENT_OVERRIDE: CURRENT,
    Register.IGNORE_POSITION_BOUNDS: INTEGER, Register.CONTROL_POSITION: POSITION,
    Register.CONTROL_VELOCITY: VELOCITY, Register.CONTROL_TORQUE: TORQUE,
    Register.POSITION_ERROR: POSITION, Register.VELOCITY_ERROR: VELOCITY,
    Register.MILLISECOND_COUNTER: INTEGER, Register.REGISTER_MAP_VERSION: INTEGER,
    Register.SET_OUTPUT_NEAREST: POSITION, Register.SET_OUTPUT_EXACT: POSITION,
}
#: the position command's registers (0x020-0x02d), which a command frame fills after its
#: mode; 0x042-0x048 are their shadows for stay-within mode (registers.md "0x042".."0x048")
COMMAND = tuple(range(Register.COMMAND_POSITION, Register.IGNORE_POSITION_BOUNDS + 1))
SHADOWS = {0x042: 0x022, 0x043: 0x023, 0x044: 0x024, 0x045: 0x025, 0x046: 0x027,
           0x047: 0x02B, 0x048: 0x02D}
#: what a mode write starts the command with (fw/bldc_servo_structs.h CommandData: position
#: and velocity 0, max torque 100 N·m, stop position NaN, feed-forward 0, scales 1, limits
#: and overrides NaN, timeout 0: the configured default)
COMMAND_DEFAULTS = {0x020: 0.0, 0x021: 0.0, 0x022: 0.0, 0x023: 1.0, 0x024: 1.0, 0x025: 100.0,
                    0x026: math.nan, 0x027: 0.0, 0x028: math.nan, 0x029: math.nan,
                    0x02A: math.nan, 0x02B: 1.0, 0x02C: math.nan, 0x02D: 0.0}
#: registers the firmware serves read-only (its ``Write`` answers kNotWriteable)
READ_ONLY = frozenset([*range(0x001, 0x008), *range(0x00A, 0x010), *range(0x038, 0x03D)]) | {
    Register.MILLISECOND_COUNTER, Register.REGISTER_MAP_VERSION}
#: registers the firmware knows and hil does not simulate (docs/protocols/moteus.md): a write
#: is taken and changes nothing (aux pins, PWM/voltage/current mode inputs, stay-within
#: bounds, clock trim, reindex, recapture), a write of a read-only one is refused as the
#: firmware refuses it, a read is answered as an unknown register's
TAKEN_UNMODELLED = frozenset([0x010, 0x011, 0x012, 0x014, 0x015, 0x016,
                              *range(0x018, 0x01F), 0x040, 0x041, 0x05C, 0x05D, 0x071,
                              *range(0x076, 0x080), 0x132, 0x133])
READ_ONLY_UNMODELLED = frozenset([*range(0x030, 0x035), 0x03D, *range(0x050, 0x056), 0x058, 0x05E,
                                  0x05F, *range(0x060, 0x06D), *range(0x072, 0x076), 0x100,
                                  0x101, 0x110, 0x120, 0x121, 0x122, 0x140, 0x141,
                                  *range(0x150, 0x154), 0x158])
#: the firmware's int32-only registers (its ``Read``: any other type is an unknown register)
INT32_ONLY = frozenset({Register.REGISTER_MAP_VERSION})
#: the register map version the firmware reports (fw/moteus_controller.cc
#: kRegisterMapVersion)
REGISTER_MAP_VERSION = 5


def scale_of(register: int) -> Scale:
    return SCALES[SHADOWS.get(register, register)]   # KeyError: a register hil does not serve


def to_raw(value: float, scale: Scale, kind: int) -> int | float:
    """A value as a register of ``scale`` carries it in type ``kind`` (the firmware's
    ``ScaleSaturate``: truncated, within +-max, NaN the minimum; ``IntMapping`` for integer
    registers)."""
    if kind == FLOAT:
        return float(value)
    if scale.lsb is None:                  # static_cast to the type: two's complement wraps
        half = LIMITS[kind] + 1
        return (int(value) + half) % (2 * half) - half if math.isfinite(value) else 0
    if not math.isfinite(value):
        return -LIMITS[kind] - 1
    limit = LIMITS[kind]
    return int(max(-limit, min(limit, value / scale.lsb[kind])))


def from_raw(raw: int | float, scale: Scale, kind: int) -> float:
    """What a register of ``scale`` means by ``raw`` of type ``kind`` (the firmware's
    ``ValueScaler``: the maximally negative integer is NaN)."""
    if kind == FLOAT or scale.lsb is None:
        return float(raw)
    if raw == -LIMITS[kind] - 1:
        return math.nan
    return raw * scale.lsb[kind]


__all__ = ["COMMAND", "COMMAND_DEFAULTS", "FAULTS", "FLOAT", "INT8", "INT16", "INT32",
           "INT32_ONLY", "LIMITS", "READ_ONLY", "READ_ONLY_UNMODELLED", "REGISTER_MAP_VERSION",
           "SHADOWS", "TAKEN_UNMODELLED", "TYPES",
           "Mode", "Register", "Scale", "from_raw", "scale_of", "to_raw"]
