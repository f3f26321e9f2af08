"""CubeMars AK actuators (AK80-9, AK60-6, AK10-9, ...) on CAN, as the maker's firmware speaks.

From the maker's document, the *AK Series Actuator Driver Manual* V1.0.8 (section 5), and
as published client libraries drive real motors (TMotorCANControl 1.2.6 for MIT and servo
mode, motor-python 0.0.11 for the V3 firmware's MIT mode):

* **MIT mode** (§5.3), firmware V2: 8-byte commands on the motor's standard id, packed as
  the mini-cheetah firmware packs them (:mod:`hil.protocols.mit`) with the model's ranges;
  ``FF x 7`` then ``FC`` enter motor mode, ``FD`` exit, ``FE`` set the zero; "the command
  to read the current state" is ``FC`` again: every frame is answered. The answer (the
  manual's "driver board sending data") is 8 bytes: the driver's id, position (16 bit),
  speed and current (12 bit each, the current on the torque range), the driver board's
  temperature (°C, signed byte) and an error code (:class:`ErrorCode`).
* **MIT mode, firmware V3** (the V3.0 motors, ``mode 8``): the command on the extended id
  ``8 << 8 | id`` with the fields reordered kp, kd, position, speed, torque; the same
  special frames on the extended id ``id``; every frame answered with the status frame
  below, as motor-python reads its AK60-6 V3.0.
* **Servo mode** (§5.1): extended ids ``mode << 8 | id`` (:class:`ServoMode`): duty,
  current, current brake, speed (electrical rpm), position (degrees x 10000), set origin,
  position-speed (degrees x 10000, speed and acceleration / 10), big-endian; no enable,
  no answer: the motor uploads its status (§5.2.1) at 1-500 Hz on the extended id
  ``0x29 << 8 | id`` (the id motor-python reads): position int16 x 0.1°, speed int16 x 10
  electrical rpm, current int16 x 0.01 A, temperature int8 °C, error code.
"""

from __future__ import annotations

import enum
import struct
from collections.abc import Mapping
from dataclasses import dataclass

from hil.can.frame import Frame, FrameSpec
from hil.protocols.base import (CarriedRange, DriveSetting, FrameSource, Protocol,
                                ProtocolOptions, Sender)
from hil.protocols.cubemars.models import MODELS, SIZED, CubeMarsModel, model
from hil.protocols.mit import (
    ENTER_MOTOR_MODE, EXIT_MOTOR_MODE, SET_ZERO, MitCommand, MitRanges, command_of_fields,
    pack_answer, uint_to_float, unpack_motion,
)
from hil.protocols.mit.family import (
    KD_MAX, KP_MAX, initial_model_options, model_figures, model_ranges, parse_gains,
    parse_model, parse_ranges, parse_standard_id, told_by_motor_id,
)

#: the id's mode byte of the status upload (0x29: motor-python's feedback id 0x2900 | id)
STATUS_MODE = 0x29
#: servo position mode's profile when none is given (§5.1: "default speed 12000 erpm,
#: acceleration 40000 erpm")
DEFAULT_ERPM, DEFAULT_ERPM_PER_S = 12000.0, 40000.0
#: the servo-mode commands' ranges: current (and brake current) -60..60 A (§5.1.2), speed
#: -100000..100000 erpm (§5.1.4). A value beyond is taken at the range's end, as the VESC
#: firmware the servo mode descends from truncates its current and speed commands (hil's
#: reading: the manual gives the ranges only)
MAX_AMPERES, MAX_ERPM = 60.0, 100000.0


class Firmware(enum.Enum):
    """Where MIT commands and their answers travel."""

    V2 = "v2"       # MIT on the standard id (the manual V1.0.8)
    V3 = "v3"       # MIT on the extended id 8 << 8 | id, answered by the status frame


class Control(enum.Enum):
    """The mode the motor runs in (chosen with the maker's R-Link tool, not over CAN)."""

    MIT = "mit"
    SERVO = "servo"


class ServoMode(enum.IntEnum):
    """The control mode in an extended id's upper bits (§5.1)."""

    DUTY = 0
    CURRENT = 1
    CURRENT_BRAKE = 2
    SPEED = 3
    POSITION = 4
    ORIGIN = 5
    POSITION_SPEED = 6
    MIT = 8             # firmware V3 only


class ErrorCode(enum.IntEnum):
    """The error code of every answer (§5.2.1)."""

    NONE = 0
    OVER_TEMPERATURE = 1
    OVER_CURRENT = 2
    OVER_VOLTAGE = 3
    UNDER_VOLTAGE = 4
    ENCODER = 5
    PHASE_CURRENT_UNBALANCE = 6


def command_id(node_id: int, mode: ServoMode) -> int:
    """The extended (29-bit) identifier of a mode's command to the motor (§5.1: the mode in
    bits 8 and up, the driver's id in bits 0-7)."""
    return mode << 8 | node_id


def status_id(node_id: int) -> int:
    """The extended identifier of the motor's status upload (§5.2.1)."""
    return STATUS_MODE << 8 | node_id


@dataclass(frozen=True)
class CubeMarsOptions(ProtocolOptions):
    """An AK motor's settings in a bus config (``options:`` of the drive)."""

    model: CubeMarsModel = MODELS["AK80-9"]
    firmware: Firmware = Firmware.V2
    control: Control = Control.MIT
    #: V2 MIT answers' id. The manual says "0X00 + Drive ID", read by the mini-cheetah
    #: firmware's users as id 0 with the drive's id in byte 0 (hil's default), by
    #: motor-python as the drive's own id: a client that checks the id needs its reading
    reply_id: int = 0
    #: the status upload's rate in servo mode, Hz (the manual: settable 1-500; 50: hil's
    #: choice, the manual gives no default)
    status_rate: float = 50.0
    #: the mapping ranges (default: the model's)
    p_max: float | None = None
    v_max: float | None = None
    t_max: float | None = None
    #: the gains hil's own master sends in MIT commands (output side)
    kp: float = 0.0
    kd: float = 0.0

    KEYS = ("model", "firmware", "control", "reply_id", "status_rate", "p_max", "v_max",
            "t_max", "kp", "kd")
    #: off: the AK manual (V1.0.8) documents no CAN timeout, so none is on by default
    WATCHDOG_TIMEOUT = 0.0

    @classmethod
    def from_mapping(cls, values: dict) -> CubeMarsOptions:
        """Raise ValueError naming the key for anything out of range."""
        found = parse_model(values, model, MODELS["AK80-9"])
        firmware = _choice(Firmware, "firmware", values.get("firmware", "v2"))
        control = _choice(Control, "control", values.get("control", "mit"))
        ranges = parse_ranges(values)
        reply_id = parse_standard_id(values, "reply_id", 0)
        rate = float(values.get("status_rate", 50.0))
        if not 1 <= rate <= 500:
            raise ValueError(f"'status_rate' {rate:g} is outside the manual's 1-500 Hz")
        kp, kd = parse_gains(values)
        return cls(found, firmware, control, reply_id, rate, kp=kp, kd=kd, **ranges)

    def drive_defaults(self) -> dict[str, float | bool]:
        """The model's published output figures, where the sources give them; no
        watchdog."""
        if not self.model.sizes:
            return super().drive_defaults()
        return {**super().drive_defaults(), **model_figures(self.model)}

    def carried_range(self) -> CarriedRange:
        ranges = self.ranges()
        return CarriedRange(ranges.p_max, ranges.v_max)

    def ranges(self) -> MitRanges:
        return model_ranges(self.model, self.p_max, self.v_max, self.t_max)

    @property
    def mit_on_standard_id(self) -> bool:
        return self.control is Control.MIT and self.firmware is Firmware.V2


def _choice(kind: type[enum.Enum], key: str, value) -> enum.Enum:
    try:
        return kind(str(value).lower())
    except ValueError:
        raise ValueError(f"'{key}' {value!r} is not one of "
                         f"{', '.join(k.value for k in kind)}") from None


# --- the frames ---------------------------------------------------------------------

@dataclass(frozen=True)
class Answer:
    """What every answer carries, in SI units at the output."""

    motor_id: int
    position: float          # rad
    velocity: float          # rad/s
    torque: float            # N·m
    temperature: int = 25    # °C, the driver board's
    error: ErrorCode = ErrorCode.NONE


def pack_mit_answer(answer: Answer, ranges: MitRanges) -> bytes:
    """The V2 MIT answer (§5.3): id, position 16, speed 12, current 12 (on the torque
    range), temperature, error."""
    return pack_answer(answer.motor_id & 0xFF, answer.position, answer.velocity, answer.torque,
                       ranges, bytes([answer.temperature & 0xFF, int(answer.error)]))


def unpack_mit_answer(data: bytes, ranges: MitRanges) -> Answer:
    """ValueError for an error code the manual does not define."""
    return Answer(data[0], *unpack_motion(data, ranges), struct.unpack("b", data[6:7])[0],
                  ErrorCode(data[7]))


_STATUS = struct.Struct(">hhhbB")


def pack_status(answer: Answer, found: CubeMarsModel) -> bytes:
    """The status upload (§5.2.1), each value clamped to its field."""
    degrees = _clamp(round(answer.position * 1800 / 3.141592653589793), 32000)
    speed = _clamp(round(found.erpm(answer.velocity) / 10), 32000)
    current = _clamp(round(answer.torque / found.torque_constant * 100), 6000)
    return _STATUS.pack(degrees, speed, current, max(-20, min(127, answer.temperature)),
                        int(answer.error))


def unpack_status(data: bytes, found: CubeMarsModel, motor_id: int) -> Answer:
    degrees, speed, current, temperature, error = _STATUS.unpack(bytes(data[:8]))
    return Answer(motor_id, degrees * 3.141592653589793 / 1800,
                  found.output_speed(speed * 10.0), current / 100 * found.torque_constant,
                  temperature, ErrorCode(error))


def _clamp(value: int, limit: int) -> int:
    return max(-limit, min(limit, value))


def unpack_v3_command(data: bytes, ranges: MitRanges) -> MitCommand:
    """A V3 MIT command: kp 12, kd 12, position 16, speed 12, torque 12 (motor-python's
    ``CubeMarsAK606v3CAN.pack_mit_frame``, "AK manual, mode ID = 8")."""
    kp, kd = (data[0] << 4) | (data[1] >> 4), ((data[1] & 0xF) << 8) | data[2]
    p, v = (data[3] << 8) | data[4], (data[5] << 4) | (data[6] >> 4)
    t = ((data[6] & 0xF) << 8) | data[7]
    return command_of_fields((uint_to_float(p, -ranges.p_max, ranges.p_max, 16),
                              uint_to_float(v, -ranges.v_max, ranges.v_max, 12),
                              uint_to_float(kp, 0.0, ranges.kp_max, 12),
                              uint_to_float(kd, 0.0, ranges.kd_max, 12),
                              uint_to_float(t, -ranges.t_max, ranges.t_max, 12)))


#: the special frames of MIT mode (§5.3), which never move a motor
SPECIAL_FRAMES = (ENTER_MOTOR_MODE, EXIT_MOTOR_MODE, SET_ZERO)


#: the modes an extended id's upper bits can name
_MODES = frozenset(ServoMode)


class CubeMars(Protocol):
    """CubeMars AK actuators in MIT or servo mode."""

    name = "cubemars"
    Options = CubeMarsOptions
    carries_torque_feed_forward = True
    has_following_error = False
    node_ids = range(1, 0x100)        # a driver id is one byte (the id's low 8 bits)
    models = SIZED
    drive = "hil.protocols.cubemars.drive:CubeMarsDrive"
    axis = "hil.protocols.cubemars.axis:CubeMarsAxis"

    @classmethod
    def initial_options(cls, setting: DriveSetting) -> dict:
        """The model (sized for the drive, else the AK80-6) with its ranges, and the master's
        MIT gains within the command's ranges."""
        return initial_model_options(setting, MODELS, "AK80-6")

    @classmethod
    def bus_frames(cls, node_id: int, cycle_hz: float, heartbeat_period: float,
                   options: CubeMarsOptions | None = None) -> list[FrameSpec]:
        options = options or CubeMarsOptions()
        if options.control is Control.SERVO:
            return [FrameSpec(command_id(node_id, ServoMode.POSITION_SPEED), 8, cycle_hz,
                              "position_speed command", extended=True),
                    FrameSpec(status_id(node_id), 8, options.status_rate, "status",
                              extended=True)]
        if options.firmware is Firmware.V3:
            return [FrameSpec(command_id(node_id, ServoMode.MIT), 8, cycle_hz, "mit command",
                              extended=True),
                    FrameSpec(status_id(node_id), 8, cycle_hz, "status", extended=True)]
        return [FrameSpec(node_id, 8, cycle_hz, "command"),
                FrameSpec(options.reply_id, 8, cycle_hz, "answer")]

    @classmethod
    def frame_source(cls, frame: Frame, drives: Mapping[int, object]) -> FrameSource | None:
        """An extended frame: ``mode << 8 | id``, a status upload or a command of that mode
        (§5.1, §5.2.1). A standard one: V2 MIT, a command to the motor's id or an answer on
        the reply id naming the motor in byte 0 (§5.3), of the drives in MIT mode on
        firmware V2 only (the others' frames are all extended)."""
        if frame.extended:
            identifier = frame.identifier
            node, mode = identifier & 0xFF, identifier >> 8
            if node not in drives:
                return None
            if mode == STATUS_MODE:
                return FrameSource(Sender.DRIVE, node, "status")
            if mode in _MODES:
                return FrameSource(Sender.MASTER, node, f"{ServoMode(mode).name.lower()} "
                                   "command", cycle=True)
            return None
        v2 = {node: options for node, options in drives.items()
              if (options or CubeMarsOptions()).mit_on_standard_id}
        return told_by_motor_id(frame, v2, {(options or CubeMarsOptions()).reply_id
                                            for options in v2.values()}, "answer")

    @classmethod
    def shared_ids(cls, options: CubeMarsOptions | None = None) -> set[int]:
        """V2 MIT answers of every motor go to one reply id (byte 0 tells whose)."""
        options = options or CubeMarsOptions()
        return {options.reply_id} if options.mit_on_standard_id else set()


__all__ = ["Answer", "Control", "CubeMars", "CubeMarsOptions", "ErrorCode", "Firmware",
           "KD_MAX", "KP_MAX", "MAX_AMPERES", "MAX_ERPM", "SPECIAL_FRAMES", "STATUS_MODE",
           "ServoMode", "command_id", "pack_mit_answer", "pack_status", "status_id",
           "unpack_mit_answer", "unpack_status", "unpack_v3_command"]
