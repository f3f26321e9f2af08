"""The MIT protocol's frames, packed as the mini-cheetah motor controller firmware packs them
(Ben Katz's Hobbyking_Cheetah_Compact, ``math_ops.cpp`` ``float_to_uint`` and
``CAN_com.cpp`` ``pack_reply`` / ``unpack_cmd``), for every motor of the family: MIT motors,
Damiao's MIT mode, CubeMars' MIT mode.

The packing is plain integer arithmetic: no library implements it (the firmware is C), and
cantools has no signals for values packed across nibbles with per-motor ranges.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import NamedTuple

ENTER_MOTOR_MODE = bytes([0xFF] * 7 + [0xFC])
EXIT_MOTOR_MODE = bytes([0xFF] * 7 + [0xFD])
SET_ZERO = bytes([0xFF] * 7 + [0xFE])


@dataclass(frozen=True)
class MitRanges:
    """Per-motor ranges of the packed values (firmware defaults: the classic mini-cheetah)."""

    p_max: float = 12.5        # rad, position in [-p_max, p_max]
    v_max: float = 65.0        # rad/s
    kp_max: float = 500.0      # N·m/rad, kp in [0, kp_max]
    kd_max: float = 5.0        # N·m·s/rad
    t_max: float = 18.0        # N·m


def float_to_uint(value: float, low: float, high: float, bits: int) -> int:
    """The firmware's packing: clamp, scale onto 0..2^bits-1, truncate."""
    value = min(max(value, low), high)
    return int((value - low) * ((1 << bits) - 1) / (high - low))


def uint_to_float(value: int, low: float, high: float, bits: int) -> float:
    return value * (high - low) / ((1 << bits) - 1) + low


class MitCommand(NamedTuple):
    """A command's values (a named tuple: one is made for every frame on each side, and a
    frozen dataclass costs four times as much to make)."""

    position: float
    velocity: float
    kp: float
    kd: float
    torque: float


#: an MitCommand from the tuple of its fields, built from C (MitCommand's own ``__new__`` is
#: a Python call, one a command on each side)
command_of_fields = functools.partial(tuple.__new__, MitCommand)


def pack_command(command: MitCommand, ranges: MitRanges) -> bytes:
    p = float_to_uint(command.position, -ranges.p_max, ranges.p_max, 16)
    v = float_to_uint(command.velocity, -ranges.v_max, ranges.v_max, 12)
    kp = float_to_uint(command.kp, 0.0, ranges.kp_max, 12)
    kd = float_to_uint(command.kd, 0.0, ranges.kd_max, 12)
    t = float_to_uint(command.torque, -ranges.t_max, ranges.t_max, 12)
    return bytes([p >> 8, p & 0xFF, v >> 4, ((v & 0xF) << 4) | (kp >> 8), kp & 0xFF, kd >> 4,
                  ((kd & 0xF) << 4) | (t >> 8), t & 0xFF])


def unpack_command(data: bytes, ranges: MitRanges) -> MitCommand:
    return command_of_fields((
        uint_to_float((data[0] << 8) | data[1], -ranges.p_max, ranges.p_max, 16),
        uint_to_float((data[2] << 4) | (data[3] >> 4), -ranges.v_max, ranges.v_max, 12),
        uint_to_float(((data[3] & 0xF) << 8) | data[4], 0.0, ranges.kp_max, 12),
        uint_to_float((data[5] << 4) | (data[6] >> 4), 0.0, ranges.kd_max, 12),
        uint_to_float(((data[6] & 0xF) << 8) | data[7], -ranges.t_max, ranges.t_max, 12)))


# --- the answer: bytes 1-5 (position 16, velocity 12, torque 12) in every family's ---------

def pack_motion(position: float, velocity: float, torque: float, ranges: MitRanges
                ) -> list[int]:
    """Bytes 1-5 of an answer, as the firmware's ``pack_reply`` lays them out; Damiao's
    feedback (its DM-J manuals; python ``damiao-motor``'s protocol page) and CubeMars' MIT
    answer (the AK manual V1.0.8 §5.3) lay them out alike, the current on the torque
    range."""
    p = float_to_uint(position, -ranges.p_max, ranges.p_max, 16)
    v = float_to_uint(velocity, -ranges.v_max, ranges.v_max, 12)
    t = float_to_uint(torque, -ranges.t_max, ranges.t_max, 12)
    return [p >> 8, p & 0xFF, v >> 4, ((v & 0xF) << 4) | (t >> 8), t & 0xFF]


def unpack_motion(data: bytes, ranges: MitRanges) -> tuple[float, float, float]:
    """Position, velocity and torque from bytes 1-5 of an answer (:func:`pack_motion`)."""
    return (uint_to_float((data[1] << 8) | data[2], -ranges.p_max, ranges.p_max, 16),
            uint_to_float((data[3] << 4) | (data[4] >> 4), -ranges.v_max, ranges.v_max, 12),
            uint_to_float(((data[4] & 0xF) << 8) | data[5], -ranges.t_max, ranges.t_max, 12))


class MitReply(NamedTuple):
    """An answer's values (a named tuple, as :class:`MitCommand`)."""

    motor_id: int
    position: float
    velocity: float
    torque: float


def pack_reply(reply: MitReply, ranges: MitRanges) -> bytes:
    return bytes([reply.motor_id, *pack_motion(reply.position, reply.velocity, reply.torque,
                                               ranges)])


def unpack_reply(data: bytes, ranges: MitRanges) -> MitReply:
    return MitReply(data[0], *unpack_motion(data, ranges))
