"""The MIT motor protocol (mini-cheetah motor controller firmware; CubeMars AK, Damiao).

A command is one 8-byte frame to the motor's CAN id: position (16 bit),
velocity, kp, kd and feed-forward torque (12 bit each), every value mapped
linearly onto its configured range and truncated to an unsigned integer, as
the firmware's ``float_to_uint`` does. Three special frames (``FF..FC``
enter motor mode, ``FF..FD`` exit, ``FF..FE`` set zero) switch the motor.
Every frame is answered with 6 bytes to the master's id: motor id, position
(16), velocity (12), torque (12). In motor mode the motor applies
``tau = kp (p_des - p) + kd (v_des - v) + t_ff`` on its shaft, saturated.

The packing is plain integer arithmetic: no library implements it (the
firmware is C), and cantools has no signals for values packed across
nibbles with per-motor ranges.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Mapping
from dataclasses import dataclass

from hil.protocols.base import DriveSetting, FrameSource, Protocol, ProtocolOptions, Sender

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


class TimeoutReaction(enum.Enum):
    """What the motor does when its CAN timeout expires in motor mode."""

    #: zero kp, kd and the feed-forward and stay in motor mode: the next command drives
    #: again (Hobbyking_Cheetah_Compact main.cpp, the 40 kHz interrupt's MOTOR_MODE case;
    #: bgkatz/motorcontrol fsm.c, ``zero_commands``)
    ZERO = "zero"
    #: leave motor mode (rest) until the next enter-motor-mode frame, as some forks of
    #: bgkatz/motorcontrol do (they drop to the menu)
    REST = "rest"


@dataclass(frozen=True)
class MitOptions(ProtocolOptions):
    """A MIT motor's settings in a bus config (``options:`` of the drive)."""

    ranges: MitRanges = MitRanges()
    reply_id: int = 0          # the master's CAN id, which every reply is sent to
    kp: float = 0.0            # the master's gains (motor side); required by the master
    kd: float = 0.0
    timeout_reaction: TimeoutReaction = TimeoutReaction.ZERO

    KEYS = ("p_max", "v_max", "kp_max", "kd_max", "t_max", "reply_id", "kp", "kd",
            "timeout_reaction")
    #: off: Hobbyking_Cheetah_Compact's main() sets CAN_TIMEOUT to 0 ("0 = none", its setup
    #: menu says) where the flash holds none (bgkatz/motorcontrol's main.c: 1000 cycles of
    #: its 25 us loop, hw_config.h's DT: 25 ms)
    WATCHDOG_TIMEOUT = 0.0

    @classmethod
    def from_mapping(cls, values: dict) -> MitOptions:
        """Raise ValueError naming the key for anything out of range."""
        ranges = MitRanges(**{k: float(values[k]) for k in
                              ("p_max", "v_max", "kp_max", "kd_max", "t_max") if k in values})
        for name in ("p_max", "v_max", "kp_max", "kd_max", "t_max"):
            if not getattr(ranges, name) > 0:
                raise ValueError(f"'{name}' must be > 0")
        reaction = str(values.get("timeout_reaction", "zero"))
        if reaction not in {r.value for r in TimeoutReaction}:
            raise ValueError(f"'timeout_reaction' {reaction!r} is not one of "
                             f"{', '.join(r.value for r in TimeoutReaction)}")
        options = cls(ranges, int(values.get("reply_id", 0)), float(values.get("kp", 0.0)),
                      float(values.get("kd", 0.0)), TimeoutReaction(reaction))
        if not 0 <= options.reply_id <= 0x7FF:
            raise ValueError(f"'reply_id' {options.reply_id} is not an 11-bit CAN id")
        if not (0 < options.kp <= ranges.kp_max and 0 <= options.kd <= ranges.kd_max):
            raise ValueError(f"'kp' must be in (0, {ranges.kp_max:g}] and 'kd' in "
                             f"[0, {ranges.kd_max:g}] (the master's motor-side gains)")
        return options


def float_to_uint(value: float, low: float, high: float, bits: int) -> int:
    """The firmware's packing: clamp, scale onto 0..2^bits-1, truncate."""
    value = min(max(value, low), high)
    return int((value - low) * ((1 << bits) - 1) / (high - low))


def uint_to_float(value: int, low: float, high: float, bits: int) -> float:
    return value * (high - low) / ((1 << bits) - 1) + low


def _field(ranges: MitRanges, name: str) -> tuple[float, float, int]:
    """(low, high, bits) of a packed value."""
    return {"position": (-ranges.p_max, ranges.p_max, 16),
            "velocity": (-ranges.v_max, ranges.v_max, 12),
            "kp": (0.0, ranges.kp_max, 12), "kd": (0.0, ranges.kd_max, 12),
            "torque": (-ranges.t_max, ranges.t_max, 12)}[name]


def _pack(values, ranges: MitRanges, names: tuple[str, ...]) -> list[int]:
    return [float_to_uint(getattr(values, name), *_field(ranges, name)) for name in names]


def _unpack(raw: tuple[int, ...], ranges: MitRanges, names: tuple[str, ...]) -> list[float]:
    return [uint_to_float(value, *_field(ranges, name)) for value, name in zip(raw, names)]


@dataclass(frozen=True)
class MitCommand:
    position: float
    velocity: float
    kp: float
    kd: float
    torque: float

    FIELDS = ("position", "velocity", "kp", "kd", "torque")


def pack_command(command: MitCommand, ranges: MitRanges) -> bytes:
    p, v, kp, kd, t = _pack(command, ranges, MitCommand.FIELDS)
    return bytes([p >> 8, p & 0xFF, v >> 4, ((v & 0xF) << 4) | (kp >> 8), kp & 0xFF, kd >> 4,
                  ((kd & 0xF) << 4) | (t >> 8), t & 0xFF])


def unpack_command(data: bytes, ranges: MitRanges) -> MitCommand:
    raw = ((data[0] << 8) | data[1], (data[2] << 4) | (data[3] >> 4),
           ((data[3] & 0xF) << 8) | data[4], (data[5] << 4) | (data[6] >> 4),
           ((data[6] & 0xF) << 8) | data[7])
    return MitCommand(*_unpack(raw, ranges, MitCommand.FIELDS))


@dataclass(frozen=True)
class MitReply:
    motor_id: int
    position: float
    velocity: float
    torque: float

    FIELDS = ("position", "velocity", "torque")


def pack_reply(reply: MitReply, ranges: MitRanges) -> bytes:
    p, v, t = _pack(reply, ranges, MitReply.FIELDS)
    return bytes([reply.motor_id, p >> 8, p & 0xFF, v >> 4, ((v & 0xF) << 4) | (t >> 8),
                  t & 0xFF])


def unpack_reply(data: bytes, ranges: MitRanges) -> MitReply:
    raw = ((data[1] << 8) | data[2], (data[3] << 4) | (data[4] >> 4),
           ((data[4] & 0xF) << 8) | data[5])
    return MitReply(data[0], *_unpack(raw, ranges, MitReply.FIELDS))


class Mit(Protocol):
    """MIT-protocol motors: one command and one reply per motor per cycle."""

    name = "mit"
    Options = MitOptions
    carries_torque_feed_forward = True
    has_following_error = False
    drive = "hil.protocols.mit.drive:MitDrive"
    axis = "hil.protocols.mit.axis:MitAxis"

    @classmethod
    def bus_frames(cls, node_id: int, cycle_hz: float, heartbeat_period: float,
                   options: MitOptions | None = None) -> list[tuple[int, int, float]]:
        options = options or MitOptions()
        return [(node_id, 8, cycle_hz), (options.reply_id, 6, cycle_hz)]

    @classmethod
    def initial_options(cls, setting: DriveSetting) -> dict:
        """Ranges covering the drive's side of its joint with a margin (1.2x; an unlimited
        joint two turns each way), and the master's gains."""
        return {"p_max": _round_up(1.2 * setting.reach), "v_max": _round_up(1.2 * setting.speed),
                "t_max": _round_up(1.2 * setting.peak_torque),
                "kp_max": _round_up(2 * setting.kp), "kd_max": _round_up(2 * setting.kd),
                "kp": float(f"{setting.kp:.4g}"), "kd": float(f"{setting.kd:.4g}")}

    @classmethod
    def frame_source(cls, can_id: int, data: bytes, remote: bool,
                     drives: Mapping[int, object]) -> FrameSource | None:
        """A command goes to the motor's id; a reply to the master's, naming the motor in
        its first byte."""
        if can_id in drives:
            return FrameSource(Sender.MASTER, can_id, "command", cycle=True)
        replies = {(options or MitOptions()).reply_id for options in drives.values()}
        if can_id in replies and data and data[0] in drives:
            return FrameSource(Sender.DRIVE, data[0], "reply")
        return None

    @classmethod
    def source_reads_data(cls, can_id: int, drives: Mapping[int, object]) -> bool:
        return can_id not in drives        # a reply names its motor in its first byte

    @classmethod
    def shared_ids(cls, options: MitOptions | None = None) -> set[int]:
        """Every motor replies to the master's one id (telling itself by the first byte)."""
        return {(options or MitOptions()).reply_id}


def _round_up(value: float) -> float:
    """Up to two significant digits (a range written by hand would look so)."""
    if value <= 0:
        return 1.0
    scale = 10 ** (math.floor(math.log10(value)) - 1)
    return float(f"{math.ceil(value / scale) * scale:.6g}")
