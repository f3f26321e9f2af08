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

from hil.can.frame import Frame, frame_of_fields

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


def frame_on_bus(identifier: int, data: bytes, fd: bool) -> Frame:
    """A frame of the family as it goes on its bus, FD with BRS where the bus is FD: a
    Damiao motor's answer (8 bytes on the master's id, FD where CAN_BR says FD,
    :mod:`hil.protocols.damiao.fd`), and a master's frame, as openarm_can sends every frame
    on an FD bus (``DMCANDevice::create_canfd_frame``: ``flags = CANFD_BRS``, ``len`` the
    payload's, 8 bytes). Built from C, here with the codec: Frame's own ``__new__`` is a
    Python call, one a frame on each side."""
    return frame_of_fields((identifier, data, False, fd, fd, False, False, 0.0))


#: an MitCommand from the tuple of its fields, built from C (MitCommand's own ``__new__`` is
#: a Python call, one a command on each side)
command_of_fields = functools.partial(tuple.__new__, MitCommand)


def pack_command(command: MitCommand, ranges: MitRanges) -> bytes:
    return pack_command_values(command.position, command.velocity, command.kp, command.kd,
                               command.torque, ranges)


def pack_command_values(position: float, velocity: float, kp: float, kd: float,
                        torque: float, ranges: MitRanges) -> bytes:
    """A command packed from its values (:func:`pack_command` without an MitCommand: a
    named tuple made costs as much as the packing, and a cycle's commands need none)."""
    p = float_to_uint(position, -ranges.p_max, ranges.p_max, 16)
    v = float_to_uint(velocity, -ranges.v_max, ranges.v_max, 12)
    kp_bits = float_to_uint(kp, 0.0, ranges.kp_max, 12)
    kd_bits = float_to_uint(kd, 0.0, ranges.kd_max, 12)
    t = float_to_uint(torque, -ranges.t_max, ranges.t_max, 12)
    return bytes([p >> 8, p & 0xFF, v >> 4, ((v & 0xF) << 4) | (kp_bits >> 8), kp_bits & 0xFF,
                  kd_bits >> 4, ((kd_bits & 0xF) << 4) | (t >> 8), t & 0xFF])


def unpack_command(data: bytes, ranges: MitRanges) -> MitCommand:
    return command_of_fields(unpack_command_values(data, ranges))


def unpack_command_values(data: bytes, ranges: MitRanges
                          ) -> tuple[float, float, float, float, float]:
    """A command's position, velocity, kp, kd and torque, in MitCommand's order, as a plain
    tuple (:func:`unpack_command` without the named tuple, for a motor's every frame)."""
    return (uint_to_float((data[0] << 8) | data[1], -ranges.p_max, ranges.p_max, 16),
            uint_to_float((data[2] << 4) | (data[3] >> 4), -ranges.v_max, ranges.v_max, 12),
            uint_to_float(((data[3] & 0xF) << 8) | data[4], 0.0, ranges.kp_max, 12),
            uint_to_float((data[5] << 4) | (data[6] >> 4), 0.0, ranges.kd_max, 12),
            uint_to_float(((data[6] & 0xF) << 8) | data[7], -ranges.t_max, ranges.t_max, 12))


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


def pack_answer(head: int, position: float, velocity: float, torque: float,
                ranges: MitRanges, tail: bytes) -> bytes:
    """A whole answer of the family in one call: byte 0 ``head`` (the motor's id; Damiao's
    state with it), bytes 1-5 the motion (:func:`pack_motion`), then ``tail`` (Damiao's
    temperatures; none in the mini-cheetah's 6-byte reply)."""
    return bytes([head, *pack_motion(position, velocity, torque, ranges)]) + tail


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
    return pack_answer(reply.motor_id, reply.position, reply.velocity, reply.torque, ranges,
                       b"")


def unpack_reply(data: bytes, ranges: MitRanges) -> MitReply:
    return MitReply(data[0], *unpack_motion(data, ranges))
