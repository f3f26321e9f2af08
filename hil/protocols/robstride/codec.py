"""The frames of Robstride's and CyberGear's private protocol and of Robstride's MIT protocol
mode, packed as the makers' documents lay them out (sections: the CyberGear instruction
manual §4, belovictor/cybergear-docs; the RS00 manual 260112's private protocol and MIT
protocol chapters; RobStride/SampleProgram ``RS/Robstride01.cpp``, the maker's RS01 code).

Private protocol (§4): CAN 2.0 extended frames, 8 data bytes; the 29-bit id carries the
communication type in bits 28-24, a 16-bit data field in bits 23-8 (the host's id in bits
15-8 of a request) and the target's id in bits 7-0.

MIT protocol mode (RS00 manual, MIT chapter): 11-bit ids ``mode << 8 | motor id`` (mode 0
the special frames and the MIT command, 1 position control, 2 speed control); the answers
on the host's id, naming the motor in byte 0.
"""

from __future__ import annotations

import enum
import struct
from dataclasses import dataclass
from typing import NamedTuple

from hil.protocols.mit import float_to_uint, uint_to_float

#: the id a device-id answer (type 0) names as its target (§4.1.1: "0xFE")
BROADCAST = 0xFE
#: the host id the maker's code uses (SampleProgram ``Master_CAN_ID = 0xFD``; the RS00
#: manual's measured default master_id 253)
DEFAULT_HOST = 0xFD
#: the id bits a frame's sender is told by: the type and the two ids, not the answer's
#: mode and fault bits (23-16)
TYPE_AND_IDS = 0x1F00FFFF


class Comm(enum.IntEnum):
    """The communication types (bits 28-24), as Robstride's code names them
    (SampleProgram ``RobStride.h``; CyberGear §4.1 has types 0-22)."""

    GET_DEVICE_ID = 0          # §4.1.1
    MOTION_CONTROL = 1         # §4.1.2, operation control mode's command
    FEEDBACK = 2               # §4.1.3
    ENABLE = 3                 # §4.1.4
    STOP = 4                   # §4.1.5; byte 0 = 1 clears faults
    SET_ZERO = 6               # §4.1.6
    SET_CAN_ID = 7             # §4.1.7
    READ_PARAMETER = 17        # §4.1.8
    WRITE_PARAMETER = 18       # §4.1.9
    FAULT_FEEDBACK = 21        # §4.1.10
    SAVE_PARAMETERS = 22       # Robstride; CyberGear's baud-rate change (§4.1.11)
    BAUD_RATE = 23             # Robstride: takes effect after a power cycle
    ACTIVE_REPORTING = 24      # Robstride
    PROTOCOL = 25              # Robstride: private / CANopen / MIT, after a power cycle


class MotorMode(enum.IntEnum):
    """The mode state of a feedback frame (bits 23-22, §4.1.3)."""

    RESET = 0
    CALIBRATION = 1
    RUN = 2


class Fault(enum.IntFlag):
    """The fault bits of a feedback frame (bits 21-16, §4.1.3; RS00: bit 20 is the stall
    overload, bit 17 the driver chip, SampleProgram ``mapFaults``)."""

    UNDERVOLTAGE = 1
    OVERCURRENT = 2            # RS: driver chip fault
    OVER_TEMPERATURE = 4
    MAGNETIC_ENCODER = 8
    HALL_ENCODER = 16
    UNCALIBRATED = 32
    #: bit 20 on the RS firmware (SampleProgram ``mapFaults``: the word's overload bit 14)
    STALL_OVERLOAD = 16


#: a feedback frame's mode and fault fields by value, looked up once a frame (an enum's call
#: is two interpreted calls, a frame a motor a cycle on each side)
MOTOR_MODES = {mode.value: mode for mode in MotorMode}
MODE_NAMES = {mode: mode.name for mode in MotorMode}
FAULTS = {bits: Fault(bits) for bits in range(64)}

#: bits 17 and 20 as the RS firmware means them (SampleProgram ``mapFaults``)
_RS_WORDS = {Fault.OVERCURRENT: "driver chip fault", Fault.STALL_OVERLOAD: "stall overload"}


def fault_words(faults: Fault, cybergear: bool) -> str:
    """A feedback frame's fault bits in the family's words."""
    words = [(None if cybergear else _RS_WORDS.get(bit)) or str(bit.name).replace("_", " ")
             for bit in Fault if bit & faults]
    return ", ".join(words).lower()


#: the fault word of a type 21 frame and MIT command 5 (§4.1.10; RS00 MIT §5.7): the bit a
#: stall overload sets (bit 14, "overload fault"), which hil reports for a drive fault
OVERLOAD_WORD_BIT = 1 << 14


class Protocol(enum.IntEnum):
    """The CAN protocol a Robstride motor speaks (type 25's byte 6, MIT command 8)."""

    PRIVATE = 0
    CANOPEN = 1
    MIT = 2


class RunMode(enum.IntEnum):
    """``run_mode`` (0x7005, §4.1.12; SampleProgram ``RobStride.h``: 1 PP, 5 CSP on the
    RS firmware; CyberGear's 1 is its position mode, following ``limit_spd``)."""

    OPERATION = 0
    POSITION_PP = 1
    SPEED = 2
    CURRENT = 3
    ZERO = 4
    POSITION_CSP = 5


def private_id(comm: int, data: int, target: int) -> int:
    """A 29-bit id: type, the 16-bit data field, the target."""
    return (comm & 0x1F) << 24 | (data & 0xFFFF) << 8 | (target & 0xFF)


@dataclass(frozen=True)
class PrivateId:
    """A 29-bit id read back."""

    comm: int
    data: int                  # bits 23-8
    target: int                # bits 7-0

    @classmethod
    def of(cls, identifier: int) -> PrivateId:
        return cls(identifier >> 24 & 0x1F, identifier >> 8 & 0xFFFF, identifier & 0xFF)

    @property
    def host(self) -> int:
        """A request's host id (bits 15-8)."""
        return self.data & 0xFF


@dataclass(frozen=True)
class Ranges:
    """What the uint fields span (the model's, or the drive's options')."""

    p_max: float
    v_max: float
    t_max: float
    kp_max: float
    kd_max: float


class Motion(NamedTuple):
    """An operation-control command (§4.1.2), SI at the output. (Named tuples, as Feedback:
    one is made a frame on each side, a frozen dataclass sets each field through
    ``object.__setattr__``.)"""

    position: float
    velocity: float
    kp: float
    kd: float
    torque: float


def pack_motion(motion: Motion, ranges: Ranges, motor_id: int) -> tuple[int, bytes]:
    """Type 1: the torque in the id's data field, the rest big-endian uint16 (§4.1.2)."""
    torque = float_to_uint(motion.torque, -ranges.t_max, ranges.t_max, 16)
    data = struct.pack(">HHHH", float_to_uint(motion.position, -ranges.p_max, ranges.p_max, 16),
                       float_to_uint(motion.velocity, -ranges.v_max, ranges.v_max, 16),
                       float_to_uint(motion.kp, 0.0, ranges.kp_max, 16),
                       float_to_uint(motion.kd, 0.0, ranges.kd_max, 16))
    return private_id(Comm.MOTION_CONTROL, torque, motor_id), data


def unpack_motion(identifier: int, data: bytes, ranges: Ranges) -> Motion:
    p, v, kp, kd = struct.unpack(">HHHH", bytes(data[:8]))
    return Motion(uint_to_float(p, -ranges.p_max, ranges.p_max, 16),
                  uint_to_float(v, -ranges.v_max, ranges.v_max, 16),
                  uint_to_float(kp, 0.0, ranges.kp_max, 16),
                  uint_to_float(kd, 0.0, ranges.kd_max, 16),
                  uint_to_float(identifier >> 8 & 0xFFFF, -ranges.t_max, ranges.t_max, 16))


class Feedback(NamedTuple):
    """What a feedback frame carries (§4.1.3), SI at the output."""

    motor_id: int
    position: float
    velocity: float
    torque: float
    temperature: float = 25.0          # °C
    mode: MotorMode = MotorMode.RESET
    faults: Fault = Fault(0)


def pack_feedback(feedback: Feedback, ranges: Ranges, host: int) -> tuple[int, bytes]:
    """Type 2: mode and faults in bits 23-16, the motor in 15-8, the host in 7-0; position,
    velocity, torque uint16 and the temperature x 10, big-endian (§4.1.3)."""
    field = int(feedback.mode) << 14 | int(feedback.faults) << 8 | feedback.motor_id
    data = struct.pack(">HHHH",
                       float_to_uint(feedback.position, -ranges.p_max, ranges.p_max, 16),
                       float_to_uint(feedback.velocity, -ranges.v_max, ranges.v_max, 16),
                       float_to_uint(feedback.torque, -ranges.t_max, ranges.t_max, 16),
                       round(feedback.temperature * 10) & 0xFFFF)
    return private_id(Comm.FEEDBACK, field, host), data


def _motor_mode(value: int) -> MotorMode:
    mode = MOTOR_MODES.get(value)
    if mode is None:
        raise ValueError(f"{value} is not a valid MotorMode")
    return mode


def unpack_feedback(identifier: int, data: bytes, ranges: Ranges) -> Feedback:
    """ValueError for a mode the manual does not define."""
    field = identifier >> 8 & 0xFFFF
    p, v, t, temperature = struct.unpack(">HHHH", bytes(data[:8]))
    return Feedback(field & 0xFF, uint_to_float(p, -ranges.p_max, ranges.p_max, 16),
                    uint_to_float(v, -ranges.v_max, ranges.v_max, 16),
                    uint_to_float(t, -ranges.t_max, ranges.t_max, 16), temperature / 10,
                    _motor_mode(field >> 14), FAULTS[field >> 8 & 0x3F])


# --- the MIT protocol mode (RS00 manual, MIT chapter) ----------------------------------------

#: the special frames' common head (MIT commands 1, 2, 4-9: FF x 6, then bytes 6 and 7)
SPECIAL_HEAD = bytes([0xFF] * 6)


class MitSpecial(enum.IntEnum):
    """Byte 7 of a special frame; byte 6 tells enable (FF) from set run mode (0-2), stop
    (FF) from switch protocol (0-2) (RS00 MIT §5.3-5.11)."""

    SET_ID = 0xFA              # command 7: byte 6 the new id
    CLEAR_OR_READ_FAULT = 0xFB  # command 5: byte 6 FF clears, else reads
    ENABLE_OR_RUN_MODE = 0xFC  # commands 1 and 6
    STOP_OR_PROTOCOL = 0xFD    # commands 2 and 8
    SET_ZERO = 0xFE            # command 4


#: byte 6 of the special frame that changes the host id (command 9: FF x 6, FD, new id)
SET_HOST_MARK = 0xFD


def mit_command_id(mode: int, motor_id: int) -> int:
    """``mode << 8 | id`` (0 special frames and MIT commands, 1 position, 2 speed)."""
    return (mode & 0x7) << 8 | (motor_id & 0xFF)


def pack_mit_answer(feedback: Feedback, ranges: Ranges) -> bytes:
    """Answer 1 (RS00 MIT §5.1): id, position 16, velocity 12, torque 12, temperature x 10
    (16 bits)."""
    p = float_to_uint(feedback.position, -ranges.p_max, ranges.p_max, 16)
    v = float_to_uint(feedback.velocity, -ranges.v_max, ranges.v_max, 12)
    t = float_to_uint(feedback.torque, -ranges.t_max, ranges.t_max, 12)
    temperature = round(feedback.temperature * 10) & 0xFFFF
    return bytes([feedback.motor_id & 0xFF, p >> 8, p & 0xFF, v >> 4, (v & 0xF) << 4 | t >> 8,
                  t & 0xFF, temperature >> 8, temperature & 0xFF])


def unpack_mit_answer(data: bytes, ranges: Ranges) -> Feedback:
    p, v = data[1] << 8 | data[2], data[3] << 4 | data[4] >> 4
    t = (data[4] & 0xF) << 8 | data[5]
    return Feedback(data[0], uint_to_float(p, -ranges.p_max, ranges.p_max, 16),
                    uint_to_float(v, -ranges.v_max, ranges.v_max, 12),
                    uint_to_float(t, -ranges.t_max, ranges.t_max, 12),
                    (data[6] << 8 | data[7]) / 10)


def pack_mit_fault(motor_id: int, word: int) -> bytes:
    """Command 5's fault answer (RS00 MIT §5.7): id, the fault word (32 bits, little-endian,
    as SampleProgram's ``memcpy`` reads it), zeros."""
    return bytes([motor_id & 0xFF]) + struct.pack("<I", word) + bytes(3)
