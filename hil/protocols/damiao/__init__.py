"""Damiao DM-J motors (DM4310, DM4340, DM8009, ...) on CAN, as the maker's firmware speaks.

From the maker's documents (the DM-J manuals' CAN protocol; Damiao's sample code
``DM_CAN.py``) and as python ``damiao-motor`` and OpenArm's ``openarm_can`` implement them:

* Commands, 8 bytes, by control mode (register 10, CTRL_MODE): MIT (1) on the motor's id
  (ESC_ID), packed as the mini-cheetah firmware packs them (:mod:`hil.protocols.mit`) with
  the motor's PMAX/VMAX/TMAX and kp 0..500, kd 0..5; position-velocity (2) on 0x100 + id
  (float32 position, float32 velocity limit); velocity (3) on 0x200 + id (float32
  velocity); force-position (4) on 0x300 + id (float32 position, uint16 velocity limit x
  100, uint16 torque limit as a fraction of TMAX x 10000). A command on the id of another
  mode than CTRL_MODE's moves nothing.
* Special frames on the motor's id: ``FF FF FF FF FF FF FF`` then ``FC`` enable, ``FD``
  disable, ``FE`` save the position zero, ``FB`` clear the error. None of them moves the
  motor (a clear-error frame is never a command).
* Every frame is answered with the feedback, 8 bytes, on the master's id (MST_ID): D0 the
  motor id (low nibble) and its state (high nibble: :class:`State`), D1-D2 position (16
  bit), D3-D5 velocity and torque (12 bit each), D6 the MOSFETs' and D7 the rotor's
  temperature (°C).
* Registers on 0x7FF (:mod:`hil.protocols.damiao.registers`): ``[id lo, id hi, op, register,
  value (4 bytes, little-endian)]``, op 0x33 read, 0x55 write, 0xAA save, 0xCC refresh; a
  read and a write are answered on the master's id with the same layout and the register's
  value (uint32 or float32 by register).
* On CAN FD (CAN_BR, register 35, an FD rate code: :mod:`hil.protocols.damiao.fd`), the same
  8-byte payloads: every answer an FD frame with the bit-rate switch, DLC 8.
"""

from __future__ import annotations

import enum
import functools
from collections.abc import Mapping
from dataclasses import dataclass
from typing import NamedTuple

from hil.can.frame import Frame, FrameSpec
from hil.protocols.base import (CanFd, CarriedRange, DriveSetting, FrameSource, Protocol,
                                ProtocolOptions, Sender, SettingField)
from hil.protocols.damiao.fd import MAX_RATE_CODE
from hil.protocols.damiao.models import MODELS, DamiaoModel, model
from hil.protocols.damiao.registers import REGISTER_ID, REGISTERS, TIMEOUT_UNIT, Op
from hil.protocols.mit import MitRanges, pack_answer, unpack_motion
from hil.protocols.mit.family import (
    initial_model_options, model_figures, model_ranges, parse_gains, parse_model, parse_ranges,
    parse_standard_id,
)

SPECIAL_PREFIX = bytes([0xFF] * 7)
ENABLE, DISABLE, SAVE_ZERO, CLEAR_ERROR = (SPECIAL_PREFIX + bytes([last])
                                           for last in (0xFC, 0xFD, 0xFE, 0xFB))


class ControlMode(enum.IntEnum):
    """CTRL_MODE (register 10), and the id offset of its commands."""

    MIT = 1
    POSITION_VELOCITY = 2
    VELOCITY = 3
    FORCE_POSITION = 4

    @property
    def id_offset(self) -> int:
        return 0x100 * (self.value - 1)


class State(enum.IntEnum):
    """The feedback's state nibble (the maker's error codes)."""

    DISABLED = 0x0
    ENABLED = 0x1
    OVER_VOLTAGE = 0x8
    UNDER_VOLTAGE = 0x9
    OVER_CURRENT = 0xA
    MOS_OVER_TEMPERATURE = 0xB
    ROTOR_OVER_TEMPERATURE = 0xC
    LOST_COMMUNICATION = 0xD
    OVERLOAD = 0xE


#: each state by its code, and in words ("LOST COMMUNICATION"), and those that report an
#: error (the maker's codes from 8 on): looked up once a feedback frame (an IntEnum's call,
#: a name's replace and a property are interpreted calls a motor a cycle on the master's side)
STATES = {state.value: state for state in State}
STATE_TEXT = {state: state.name.replace("_", " ") for state in State}
ERROR_STATES = frozenset(state for state in State if state >= State.OVER_VOLTAGE)


@dataclass(frozen=True)
class DamiaoOptions(ProtocolOptions):
    """A Damiao motor's settings in a bus config (``options:`` of the drive)."""

    model: DamiaoModel = MODELS["DM4310"]
    #: MST_ID: the id the motor answers on (default: its own id + 0x10, as the maker's
    #: guides recommend)
    master_id: int | None = None
    #: the mapping ranges (PMAX, VMAX, TMAX registers; default: the model's)
    p_max: float | None = None
    v_max: float | None = None
    t_max: float | None = None
    control_mode: ControlMode = ControlMode.MIT
    #: the gains hil's own master sends in MIT commands (output side; 0: the drive's
    #: tuning, see hil.protocols.damiao.axis)
    kp: float = 0.0
    kd: float = 0.0
    #: CAN_BR (register 35), the motor's rate code: classic 0-4 or CAN FD 5-11
    #: (:mod:`hil.protocols.damiao.fd`); None: its bus' rates (hil's choice: a motor set up
    #: for its bus, as Damiao's tool sets it)
    can_br: int | None = None

    KEYS = ("model", "master_id", "p_max", "v_max", "t_max", "control_mode", "kp", "kd",
            "can_br")
    #: off: TIMEOUT (register 9) is 0 in the factory configuration, as the DM4310's firmware
    #: writes it to an erased flash (recovered in github.com/umeow0716/damiao_firmware,
    #: app/src/app_config.c, ``communication_timeout = 0``)
    WATCHDOG_TIMEOUT = 0.0

    @classmethod
    def from_mapping(cls, values: dict) -> DamiaoOptions:
        """Raise ValueError naming the key for anything out of range."""
        found = parse_model(values, model, MODELS["DM4310"])
        ranges = parse_ranges(values)
        mode = values.get("control_mode", "MIT")
        try:
            mode = ControlMode[str(mode).upper()] if not isinstance(mode, int) \
                else ControlMode(mode)
        except (KeyError, ValueError):
            raise ValueError(f"'control_mode' {mode!r} is not one of "
                             f"{', '.join(m.name for m in ControlMode)}") from None
        master = parse_standard_id(values, "master_id", None)
        kp, kd = parse_gains(values)
        return cls(found, master, control_mode=mode, kp=kp, kd=kd,
                   can_br=parse_rate_code(values.get("can_br")), **ranges)

    def drive_defaults(self) -> dict[str, float | bool]:
        """The model's output-shaft figures: peak and rated torque, no-load speed; no
        holding brake (the DM-J manuals list none); TIMEOUT's factory value."""
        return {**super().drive_defaults(), **model_figures(self.model)}

    def reply_id(self, node_id: int) -> int:
        return self.master_id if self.master_id is not None else node_id + 0x10

    def carried_range(self) -> CarriedRange:
        ranges = self.ranges()
        return CarriedRange(ranges.p_max, ranges.v_max)

    def ranges(self) -> MitRanges:
        """The MIT mapping the motor starts with (its PMAX/VMAX/TMAX registers)."""
        return model_ranges(self.model, self.p_max, self.v_max, self.t_max)


def parse_rate_code(value) -> int | None:
    """CAN_BR as the options give it; ValueError for a code the firmware has not."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= MAX_RATE_CODE:
        raise ValueError(f"'can_br' {value!r} is not a rate code 0-{MAX_RATE_CODE} (0-4 "
                         "classic CAN, 5-11 CAN FD)")
    return value


class Feedback(NamedTuple):
    """A feedback frame's values (a named tuple: one is made for every answer on each side,
    as :class:`hil.protocols.mit.MitReply`)."""

    motor_id: int          # the low nibble of the motor's id
    state: State
    position: float
    velocity: float
    torque: float
    mos_temperature: int = 25
    rotor_temperature: int = 25


#: a Feedback from the tuple of all its fields, built from C (Feedback's own ``__new__`` is
#: a Python call, one an answer on each side)
feedback_of_fields = functools.partial(tuple.__new__, Feedback)


def pack_feedback(feedback: Feedback, ranges: MitRanges) -> bytes:
    return pack_answer(feedback_head(feedback.motor_id, feedback.state), feedback.position,
                       feedback.velocity, feedback.torque, ranges,
                       bytes([feedback.mos_temperature & 0xFF,
                              feedback.rotor_temperature & 0xFF]))


def feedback_head(motor_id: int, state: State) -> int:
    """D0 of the feedback: the state in the high nibble, the motor's id in the low one."""
    return (state << 4) | (motor_id & 0x0F)


def unpack_feedback(data: bytes, ranges: MitRanges) -> Feedback:
    """ValueError for a state code the maker does not define."""
    state = STATES.get(data[0] >> 4)
    if state is None:
        raise ValueError(f"{data[0] >> 4} is not a state the maker defines")
    return feedback_of_fields((data[0] & 0x0F, state, *unpack_motion(data, ranges),
                               data[6], data[7]))


def is_register_answer(data: bytes) -> bool:
    """Whether a frame on the master's id answers a register request, not feedback: byte 1
    an id's high byte (at most 7), byte 2 0x33 or 0x55, byte 3 a register, as the maker's
    sample code and python ``damiao-motor`` tell them apart (feedback can look so only
    with the position within a few per mille of -PMAX)."""
    return (len(data) == 8 and data[1] <= 0x07 and data[2] in (Op.READ, Op.WRITE)
            and data[3] in REGISTERS)


class Damiao(Protocol):
    """Damiao DM-J motors: a command and its feedback per motor per cycle."""

    name = "damiao"
    Options = DamiaoOptions
    carries_torque_feed_forward = True
    has_following_error = False
    node_ids = range(1, 0x100)          # the mode offsets 0x100..0x300 must not collide
    #: classic CAN or CAN FD by CAN_BR, which follows the bus (hil.protocols.damiao.fd)
    can_fd = CanFd.FOLLOWS_BUS
    models = MODELS
    setting_fields = {"watchdog_timeout": SettingField(1 / TIMEOUT_UNIT, 0, 0xFFFFFFFF,
                                                       "register 9 TIMEOUT, uint32 of 50 us")}
    drive = "hil.protocols.damiao.drive:DamiaoDrive"
    axis = "hil.protocols.damiao.axis:DamiaoAxis"

    @classmethod
    def initial_options(cls, setting: DriveSetting) -> dict:
        """The model (sized for the drive, else the DM4310) with its ranges, and the
        master's MIT gains within the command's ranges."""
        return initial_model_options(setting, MODELS, "DM4310")

    @classmethod
    def bus_frames(cls, node_id: int, cycle_hz: float, heartbeat_period: float,
                   options: DamiaoOptions | None = None) -> list[FrameSpec]:
        options = options or DamiaoOptions()
        command = node_id + options.control_mode.id_offset
        return [FrameSpec(command, 8, cycle_hz, "command"),
                FrameSpec(options.reply_id(node_id), 8, cycle_hz, "feedback")]

    @classmethod
    def frame_source(cls, frame: Frame, drives: Mapping[int, object]) -> FrameSource | None:
        """Commands go to a motor's id (plus its mode's offset), register requests to 0x7FF
        naming the motor in bytes 0-1; answers come on its master id; all of them 11-bit
        frames (python ``damiao-motor`` sends ``is_extended_id=False``): an extended frame
        is no DM-J motor's."""
        if frame.extended:
            return None
        can_id, data = frame.identifier, frame.data
        if can_id == REGISTER_ID and len(data) >= 2:
            node = data[0] | (data[1] << 8)
            return FrameSource(Sender.MASTER, node, "register") if node in drives else None
        node = can_id & 0xFF
        if node in drives and can_id - node in (m.id_offset for m in ControlMode):
            return FrameSource(Sender.MASTER, node, "command", cycle=True)
        for node, options in drives.items():
            if can_id == (options or DamiaoOptions()).reply_id(node) and data and (
                    (data[0] & 0x0F) == (node & 0x0F)):
                return FrameSource(Sender.DRIVE, node, "feedback")
        return None

    @classmethod
    def source_reads_data(cls, frame: Frame, drives: Mapping[int, object]) -> bool:
        return True          # register requests and feedback name their motor in the data

    @classmethod
    def shared_ids(cls, options: DamiaoOptions | None = None) -> set[int]:
        """Every motor takes register requests on 0x7FF (telling its own by bytes 0-1)."""
        return {REGISTER_ID}


__all__ = ["CLEAR_ERROR", "DISABLE", "ENABLE", "SAVE_ZERO", "ControlMode", "Damiao",
           "DamiaoOptions", "Feedback", "Op", "REGISTER_ID", "STATE_TEXT", "STATES", "State",
           "TIMEOUT_UNIT",
           "is_register_answer", "pack_feedback", "unpack_feedback"]
