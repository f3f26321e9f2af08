"""MyActuator RMD frames, byte for byte, as the maker's *Motor Motion Control Command
Protocol* V4.2 (2024-05, "applicable driver: V3") lays them out: every frame 8 bytes,
little-endian, the command byte first (§1.1.2, §2).

Ids (§1.1.2): a command to one motor on ``0x140 + id`` (id 1-32), its reply on ``0x240 +
id``; a command to every motor on ``0x280`` (§3, each answers on its own reply id); the
CANID setting command on ``0x300`` (§4); the motion mode (MIT) command on ``0x400 + id``,
its reply on ``0x500 + id`` (§5).
"""

from __future__ import annotations

import enum
import math
import struct
from dataclasses import dataclass

from hil.protocols.mit import MitRanges, pack_motion, unpack_motion

COMMAND_BASE, REPLY_BASE = 0x140, 0x240          # §1.1.2
MULTI_MOTOR_ID = 0x280                            # §3
CANID_SETTING_ID = 0x300                          # §4
MIT_BASE, MIT_REPLY_BASE = 0x400, 0x500           # §5
#: the ids a motor can have (§1.1.2: "ID(1~32)")
MOTOR_IDS = range(1, 33)
#: the motor encoder's lines: §2.15.4's example ("the number of lines of the motor encoder
#: is 16384 and the reduction ratio is 6, then 360 degrees of the output shaft corresponds to
#: 16384*6 = 98304 pulses"); hil takes it for every model (the document gives no other)
ENCODER_LINES = 16384
#: the motion mode's ranges (§5.1): p_des ±12.5 rad, v_des ±45 rad/s, t_ff ±24 N·m, kp
#: 0-500, kd 0-5
MIT_RANGES = MitRanges(p_max=12.5, v_max=45.0, kp_max=500.0, kd_max=5.0, t_max=24.0)


class Command(enum.IntEnum):
    """Every command byte of the document (§2, §4), named as its heading names it."""

    READ_PID = 0x30                    # §2.1
    WRITE_PID_RAM = 0x31               # §2.2
    WRITE_PID_ROM = 0x32               # §2.3
    READ_ACCELERATION = 0x42           # §2.4
    WRITE_ACCELERATION = 0x43          # §2.5
    READ_MULTI_TURN_ENCODER = 0x60     # §2.6
    READ_MULTI_TURN_ORIGINAL = 0x61    # §2.7
    READ_MULTI_TURN_ZERO_OFFSET = 0x62  # §2.8
    WRITE_ENCODER_ZERO = 0x63          # §2.9
    WRITE_CURRENT_ZERO = 0x64          # §2.10
    READ_SINGLE_TURN_ENCODER = 0x90    # §2.11
    READ_MULTI_TURN_ANGLE = 0x92       # §2.12
    READ_SINGLE_TURN_ANGLE = 0x94      # §2.13
    READ_STATUS_1 = 0x9A               # §2.14
    READ_STATUS_2 = 0x9C               # §2.15
    READ_STATUS_3 = 0x9D               # §2.16
    SHUTDOWN = 0x80                    # §2.17
    STOP = 0x81                        # §2.18
    TORQUE = 0xA1                      # §2.19
    SPEED = 0xA2                       # §2.20
    ABSOLUTE_POSITION = 0xA4           # §2.21
    SINGLE_TURN_POSITION = 0xA6        # §2.22
    INCREMENTAL_POSITION = 0xA8        # §2.23
    READ_OPERATING_MODE = 0x70         # §2.24
    READ_POWER = 0x71                  # not in V4.2: 2b-t/myactuator_rmd's READ_MOTOR_POWER
    RESET = 0x76                       # §2.25
    BRAKE_RELEASE = 0x77               # §2.26
    BRAKE_LOCK = 0x78                  # §2.27
    CANID = 0x79                       # §4
    READ_RUNTIME = 0xB1                # §2.28
    READ_VERSION_DATE = 0xB2           # §2.29
    CAN_TIMEOUT = 0xB3                 # §2.30
    BAUD_RATE = 0xB4                   # §2.31
    READ_MODEL = 0xB5                  # §2.32
    ACTIVE_REPLY = 0xB6                # §2.33
    FUNCTION_CONTROL = 0x20            # §2.34

    @property
    def words(self) -> str:
        """The command as a log and ``hil describe`` name it (``0xA4 absolute position``)."""
        return f"0x{self.value:02X} {self.name.lower().replace('_', ' ')}"


#: the closed-loop control commands (§2.19-2.23): "a control command, which can be run when
#: the motor is not faulty"
CONTROL = frozenset({Command.TORQUE, Command.SPEED, Command.ABSOLUTE_POSITION,
                     Command.SINGLE_TURN_POSITION, Command.INCREMENTAL_POSITION})


class ErrorState(enum.IntFlag):
    """Motor status 1's error flags (§2.14.3, System_errorState); several add up."""

    MOTOR_STALL = 0x0002
    LOW_VOLTAGE = 0x0004
    OVER_VOLTAGE = 0x0008
    OVER_CURRENT = 0x0010
    POWER_OVERRUN = 0x0040
    CALIBRATION_WRITE = 0x0080
    SPEEDING = 0x0100
    OVER_TEMPERATURE = 0x1000
    ENCODER_CALIBRATION = 0x2000


class RunMode(enum.IntEnum):
    """The operating mode 0x70 answers (§2.24.3); 0 after a shutdown, which "clears the
    motor running state, not in any closed loop mode" (§2.17.1; 2b-t/myactuator_rmd's
    ControlMode::NONE)."""

    NONE = 0
    CURRENT = 1
    SPEED = 2
    POSITION = 3


@dataclass(frozen=True)
class MotorState:
    """What the control commands' replies and status 2 carry (§2.15.3, §2.19.3)."""

    temperature: int       # °C
    iq: float              # A, torque current
    speed: float           # dps, output shaft
    angle: float           # degrees, output shaft (0xA6's reply: encoder pulses)


_STATE = struct.Struct("<Bbhhh")
_STATE_A6 = struct.Struct("<BbhhH")


def _clamp(value: float, low: int, high: int) -> int:
    return max(low, min(high, round(value)))


def pack_state(command: int, state: MotorState) -> bytes:
    """A control command's reply or status 2: temperature int8, iq int16 0.01 A, speed
    int16 1 dps, angle int16 1° (0xA6: the encoder as uint16, §2.22.3), each clamped to
    its field."""
    if command == Command.SINGLE_TURN_POSITION:
        return _STATE_A6.pack(command, _clamp(state.temperature, -128, 127),
                              _clamp(state.iq * 100, -32768, 32767),
                              _clamp(state.speed, -32768, 32767), int(state.angle) & 0xFFFF)
    return _STATE.pack(command, _clamp(state.temperature, -128, 127),
                       _clamp(state.iq * 100, -32768, 32767),
                       _clamp(state.speed, -32768, 32767), _clamp(state.angle, -32767, 32767))


def unpack_state(data: bytes) -> MotorState:
    layout = _STATE_A6 if data[0] == Command.SINGLE_TURN_POSITION else _STATE
    _, temperature, iq, speed, angle = layout.unpack(bytes(data[:8]))
    return MotorState(temperature, iq / 100, speed, angle)


_STATUS_1 = struct.Struct("<BbxBHH")


def pack_status_1(temperature: int, brake_released: bool, volts: float,
                  error: ErrorState) -> bytes:
    """0x9A's reply (§2.14.3): temperature, brake release command, voltage 0.1 V, error
    flags."""
    return _STATUS_1.pack(Command.READ_STATUS_1, _clamp(temperature, -128, 127),
                          int(brake_released), _clamp(volts * 10, 0, 0xFFFF), int(error))


def unpack_status_1(data: bytes) -> tuple[int, bool, float, ErrorState]:
    _, temperature, brake, volts, error = _STATUS_1.unpack(bytes(data[:8]))
    return temperature, bool(brake), volts / 10, ErrorState(error)


def pack_phase_currents(temperature: int, iq: float, electrical_angle: float) -> bytes:
    """0x9D's reply (§2.16.3): temperature and the three phase currents (0.01 A). hil
    models the q-axis current only: the phases are its inverse Park transform at the
    rotor's electrical angle (no d-axis current; hil's reading)."""
    phases = (-iq * math.sin(electrical_angle - shift) for shift in
              (0.0, 2 * math.pi / 3, -2 * math.pi / 3))
    return struct.pack("<Bb3h", Command.READ_STATUS_3, _clamp(temperature, -128, 127),
                       *(_clamp(phase * 100, -32768, 32767) for phase in phases))


def with_value(data: bytes, value: int, signed: bool = True) -> bytes:
    """``data`` with bytes 4-7 holding ``value`` (the layout of every read command's
    32-bit answer, §2.4-2.12, §2.28-2.30)."""
    return bytes(data[:4]) + struct.pack("<i" if signed else "<I", value)


def value_of(data: bytes, signed: bool = True) -> int:
    return struct.unpack_from("<i" if signed else "<I", bytes(data), 4)[0]


def pack_mit_reply(node_id: int, position: float, velocity: float, torque: float) -> bytes:
    """The motion mode's reply (§5.3): the motor's id, position 16 bit, speed 12, torque
    12 (the mini-cheetah layout), two NULL bytes."""
    return bytes([node_id & 0xFF, *pack_motion(position, velocity, torque, MIT_RANGES), 0, 0])


def unpack_mit_reply(data: bytes) -> tuple[int, float, float, float]:
    return (data[0], *unpack_motion(data, MIT_RANGES))
