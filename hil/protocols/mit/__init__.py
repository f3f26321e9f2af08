"""The MIT motor protocol (mini-cheetah motor controller firmware; CubeMars AK, Damiao).

A command is one 8-byte frame to the motor's CAN id: position (16 bit),
velocity, kp, kd and feed-forward torque (12 bit each), every value mapped
linearly onto its configured range and truncated to an unsigned integer, as
the firmware's ``float_to_uint`` does. Three special frames (``FF..FC``
enter motor mode, ``FF..FD`` exit, ``FF..FE`` set zero) switch the motor.
Every frame is answered with 6 bytes to the master's id: motor id, position
(16), velocity (12), torque (12). In motor mode the motor applies
``tau = kp (p_des - p) + kd (v_des - v) + t_ff`` on its shaft, saturated.

The frames' packing: :mod:`hil.protocols.mit.codec`; what Damiao and CubeMars share with
it: :mod:`hil.protocols.mit.family`.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Mapping
from dataclasses import dataclass

from hil.can.frame import Frame, FrameSpec
from hil.compiled import COMPILED_MIT_CODEC, import_fresh

# the codec's build (setup.py), loaded before anything imports it
import_fresh(*COMPILED_MIT_CODEC)

from hil.protocols.base import (  # noqa: E402
    CarriedRange, DriveSetting, FrameSource, Protocol, ProtocolOptions)
from hil.protocols.mit.codec import (  # noqa: E402
    ENTER_MOTOR_MODE, EXIT_MOTOR_MODE, SET_ZERO, MitCommand, MitRanges, MitReply,
    command_of_fields, float_to_uint, frame_on_bus, pack_answer, pack_command, pack_command_values,
    pack_motion, pack_reply, uint_to_float, unpack_command, unpack_command_values,
    unpack_motion, unpack_reply,
)
from hil.protocols.mit.family import parse_standard_id, told_by_motor_id  # noqa: E402


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

    def carried_range(self) -> CarriedRange:
        return CarriedRange(self.ranges.p_max, self.ranges.v_max)

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
        options = cls(ranges, parse_standard_id(values, "reply_id", 0),
                      float(values.get("kp", 0.0)), float(values.get("kd", 0.0)),
                      TimeoutReaction(reaction))
        if not (0 < options.kp <= ranges.kp_max and 0 <= options.kd <= ranges.kd_max):
            raise ValueError(f"'kp' must be in (0, {ranges.kp_max:g}] and 'kd' in "
                             f"[0, {ranges.kd_max:g}] (the master's motor-side gains)")
        return options


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
                   options: MitOptions | None = None) -> list[FrameSpec]:
        options = options or MitOptions()
        return [FrameSpec(node_id, 8, cycle_hz, "command"),
                FrameSpec(options.reply_id, 6, cycle_hz, "reply")]

    @classmethod
    def initial_options(cls, setting: DriveSetting) -> dict:
        """Ranges covering the drive's side of its joint with a margin (1.2x; an unlimited
        joint two turns each way), and the master's gains."""
        return {"p_max": _round_up(1.2 * setting.reach), "v_max": _round_up(1.2 * setting.speed),
                "t_max": _round_up(1.2 * setting.peak_torque),
                "kp_max": _round_up(2 * setting.kp), "kd_max": _round_up(2 * setting.kd),
                "kp": float(f"{setting.kp:.4g}"), "kd": float(f"{setting.kd:.4g}")}

    @classmethod
    def frame_source(cls, frame: Frame, drives: Mapping[int, object]) -> FrameSource | None:
        """A command goes to the motor's id; a reply to the master's, naming the motor in
        its first byte; both are 11-bit frames (an extended one is no MIT motor's)."""
        if frame.extended:
            return None
        return told_by_motor_id(frame, drives, {(options or MitOptions()).reply_id
                                                for options in drives.values()}, "reply")

    @classmethod
    def source_reads_data(cls, frame: Frame, drives: Mapping[int, object]) -> bool:
        # a reply names its motor in its first byte; an extended frame: told by its flag,
        # kept apart from the 11-bit frame of its number whatever a reader keys its answers by
        return frame.extended or frame.identifier not in drives

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


__all__ = ["ENTER_MOTOR_MODE", "EXIT_MOTOR_MODE", "SET_ZERO", "Mit", "MitCommand", "MitOptions",
           "MitRanges", "MitReply", "TimeoutReaction", "command_of_fields", "float_to_uint",
           "frame_on_bus", "pack_answer", "pack_command", "pack_command_values", "pack_motion",
           "pack_reply", "uint_to_float", "unpack_command", "unpack_command_values",
           "unpack_motion", "unpack_reply"]
