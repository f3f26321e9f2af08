"""Damiao's DM-IMU-L1 on CAN, as the maker documents it: "达妙科技DM-IMU-L1六轴IMU模块使用说明书
V1.1" (the user manual, section 3 "CAN 通信" and appendices 2 and 3), its firmware logs and
sample code (github.com/dmBots/DM-IMU: 04.固件/V1023固件更新日志.pdf,
02.例程/MC02_CAN收发例程/DM-IMU/dm_imu.c).

The IMU answers requests only ("一发一收": one request, one answer), classical CAN at
1 Mbit/s, which the firmware cannot change. A request names a register:

====  ==================  ======================================================
RID   register            answer (8 bytes at the master id, MST_ID)
0x01  acceleration        RID, temperature (°C, not mapped), x, y, z: uint16 LE
0x02  angular velocity    RID, 0, x, y, z: uint16 LE
0x03  Euler angles        RID, 0, pitch, yaw, roll: uint16 LE
0x04  quaternion          RID, then w, x, y, z as 14-bit fields, most significant first
====  ==================  ======================================================

Each value is mapped linearly onto its field, as appendix 2's ``float_to_uint`` does:
(value - min) · (2^bits - 1) / (max - min), truncated; accelerations within ±58.8 m/s²
(±6 g; ±235.2 from firmware 1023, "提升加速度计量程至 24g"), angular velocities within
±34.88 rad/s, pitch within ±90°, yaw and roll within ±180°, quaternion parts within ±1.

The request's form is the firmware's:

* up to 1022 (the manual): identifier 0x6FF, 4 bytes: CANID low, CANID high, RID, 0xCC;
* 1023 (its log: "请求数据报文帧 ID 由 0x6FF 修改为设置的 can_id"): the same 4 bytes at
  the IMU's own CAN id;
* 1024 (the sample code adapted to it): 8 bytes at its CAN id: 0xCC, RID, 0 (read) or
  1 (write), 0xDD, a uint32 LE value.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

import numpy as np

from hil.can.frame import Frame, FrameSpec
from hil.protocols.imu import ImuReading, ImuSample, euler_angles, reading_of

ACCELERATION, ANGULAR_VELOCITY, ANGLE, QUATERNION = 0x01, 0x02, 0x03, 0x04
#: the registers by the names a bus config's ``outputs`` give, in the manual's order
OUTPUTS = {"acceleration": ACCELERATION, "angular_velocity": ANGULAR_VELOCITY,
           "angle": ANGLE, "quaternion": QUATERNION}
NAMES = {register: name for name, register in OUTPUTS.items()}
#: the manual's request identifier (firmware up to 1022)
LEGACY_REQUEST_ID = 0x6FF
REQUEST_MARK, WRITE_MARK = 0xCC, 0xDD
READ, WRITE = 0, 1
#: the maker's sample code's ids (imu_init(0x01, 0x11, ...)): the IMU's CAN id and the
#: master id it answers on; the manual states no factory value
DEFAULT_NODE_ID, DEFAULT_MASTER_ID = 0x01, 0x11
#: the bus' bit rate the firmware speaks (the manual: "当前固件版本无法调整")
BITRATE = 1_000_000
#: the output rates the product offers (the manual's USB command table, 100-1000 Hz)
RATES_HZ = (100.0, 125.0, 200.0, 250.0, 500.0, 1000.0)
GYRO_MAX = 34.88                               # rad/s (±2000 °/s)
PITCH_MAX, YAW_MAX, ROLL_MAX = 90.0, 180.0, 180.0     # degrees
#: the temperature byte of the acceleration answer: hil models no temperature and sends
#: the manual's test condition, 25 °C (the manual's reader does not read it)
TEMPERATURE_C = 25


@dataclass(frozen=True)
class Firmware:
    """What the firmware's version decides on the wire."""

    version: int
    accelerometer_max: float                   # m/s², either side of zero
    legacy_request: bool                       # at 0x6FF (the manual), else at the CAN id
    long_request: bool                         # the 8-byte 0xCC RID RW 0xDD form (1024)

    def request_id(self, node_id: int) -> int:
        """The identifier its master's requests come on."""
        return LEGACY_REQUEST_ID if self.legacy_request else node_id


FIRMWARES = {1022: Firmware(1022, 58.8, legacy_request=True, long_request=False),
             1023: Firmware(1023, 235.2, legacy_request=False, long_request=False),
             1024: Firmware(1024, 235.2, legacy_request=False, long_request=True)}
#: the manual's protocol unless a config says otherwise
DEFAULT_FIRMWARE = 1022


def to_field(value: float, top: float, bits: int = 16) -> int:
    """``value`` in ±``top`` as the manual's float_to_uint maps it: truncated, held at the
    field's ends (hil's reading: the sensor saturates, the C cast's wrap is not the product);
    NaN as an Arm Cortex-M's float-to-integer conversion gives it, 0 (hil's choice: the
    manual does not name its processor)."""
    steps = (1 << bits) - 1
    mapped = (value + top) * steps / (2 * top)
    if mapped != mapped:
        return 0
    return int(min(max(mapped, 0.0), steps))


def from_field(raw: int, top: float, bits: int = 16) -> float:
    """A field's value as the manual's uint_to_float reads it."""
    return raw * (2 * top) / ((1 << bits) - 1) - top


def orientation_step(outputs: tuple[int, ...]) -> float:
    """The angle (rad) one count of the orientation a reader takes stands for: the
    quaternion's 14-bit parts' (a part's step moves the angle about twice as far) where it
    is sent, else yaw's and roll's 16-bit fields'."""
    if QUATERNION in outputs:
        return 2 * 2 / ((1 << 14) - 1)
    return math.radians(2 * YAW_MAX / ((1 << 16) - 1))


def answer(sample: ImuSample, register: int, master_id: int, firmware: Firmware) -> Frame:
    """The answer to a request of ``register``, from ``sample``."""
    if register == QUATERNION:
        q = sample.orientation if sample.orientation[0] >= 0 else -sample.orientation
        w, x, y, z = (to_field(float(v), 1.0, 14) for v in q)
        packed = (w << 42) | (x << 28) | (y << 14) | z            # 56 bits, w first
        return Frame(master_id, bytes((register,)) + packed.to_bytes(7, "big"))
    if register == ACCELERATION:
        top = firmware.accelerometer_max
        values = [to_field(float(v), top) for v in sample.acceleration]
        second = TEMPERATURE_C
    elif register == ANGULAR_VELOCITY:
        values = [to_field(float(v), GYRO_MAX) for v in sample.angular_velocity]
        second = 0
    elif register == ANGLE:
        roll, pitch, yaw = (math.degrees(a) for a in euler_angles(sample.orientation))
        values = [to_field(pitch, PITCH_MAX), to_field(yaw, YAW_MAX), to_field(roll, ROLL_MAX)]
        second = 0
    else:
        raise ValueError(f"no DM-IMU register 0x{register:02X}")
    return Frame(master_id, struct.pack("<BB3H", register, second, *values))


def request(register: int, node_id: int, firmware: Firmware) -> Frame:
    """A master's request of ``register`` from the IMU of ``node_id``."""
    if firmware.long_request:
        return Frame(node_id, struct.pack("<BBBBI", REQUEST_MARK, register, READ, WRITE_MARK,
                                          0))
    return Frame(firmware.request_id(node_id),
                 struct.pack("<HBB", node_id, register, REQUEST_MARK))


def requested(frame: Frame, node_id: int, firmware: Firmware) -> int | None:
    """The register a frame at the IMU's request id asks for; None if it is not a read
    request of a data register to this IMU (another IMU's, a write, a malformed frame)."""
    data = frame.data
    if firmware.long_request:
        if (len(data) != 8 or data[0] != REQUEST_MARK or data[3] != WRITE_MARK
                or data[2] != READ):
            return None
        register = data[1]
    else:
        if len(data) != 4 or data[3] != REQUEST_MARK or data[0] | data[1] << 8 != node_id:
            return None
        register = data[2]
    return register if register in NAMES else None


def frame_specs(node_id: int, master_id: int, poll_hz: float, outputs: tuple[int, ...],
                firmware: Firmware, what: str) -> list[FrameSpec]:
    """Its frames on the bus: its master's requests, one per output every 1/``poll_hz`` s,
    and their answers (for the bus' load and its ids; a replay tells them by these)."""
    rate = poll_hz * len(outputs)
    length = 8 if firmware.long_request else 4
    return [FrameSpec(firmware.request_id(node_id), length, rate, f"{what} request"),
            FrameSpec(master_id, 8, rate, f"{what} answer")]


class AnswerReader:
    """Answers as samples, decoded as the manual's reader decodes them: one complete when
    the answer of the last of ``outputs`` arrives (a frame of another length or register
    is counted in :attr:`bad_frames` and skipped)."""

    def __init__(self, outputs: tuple[int, ...], firmware: Firmware):
        self._last = outputs[-1]
        self._firmware = firmware
        self._fields: dict[int, np.ndarray] = {}
        self.bad_frames = 0

    def feed(self, frame: Frame) -> ImuReading | None:
        """The sample ``frame`` completes, if it does."""
        data = frame.data
        if len(data) != 8 or data[0] not in NAMES:
            self.bad_frames += 1
            return None
        register = data[0]
        self._fields[register] = self._decode(register, data)
        if register != self._last:
            return None
        fields, self._fields = self._fields, {}
        angles = None
        if ANGLE in fields:
            pitch, yaw, roll = np.radians(fields[ANGLE])
            angles = (roll, pitch, yaw)
        return reading_of(fields.get(ACCELERATION), fields.get(ANGULAR_VELOCITY),
                          fields.get(QUATERNION), angles)

    def _decode(self, register: int, data: bytes) -> np.ndarray:
        if register == QUATERNION:
            packed = int.from_bytes(data[1:], "big")
            return np.array([from_field((packed >> shift) & 0x3FFF, 1.0, 14)
                             for shift in (42, 28, 14, 0)])
        raw = struct.unpack_from("<3H", data, 2)
        if register == ANGLE:
            return np.array([from_field(raw[0], PITCH_MAX), from_field(raw[1], YAW_MAX),
                             from_field(raw[2], ROLL_MAX)])
        top = self._firmware.accelerometer_max if register == ACCELERATION else GYRO_MAX
        return np.array([from_field(r, top) for r in raw])
