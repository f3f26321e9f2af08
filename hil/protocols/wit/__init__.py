"""WitMotion's serial protocol (WT901, HWT905 and the HiWonder IMUs built on them): what an
IMU of the family sends over its USB serial port, as its maker's "WIT standard protocol"
manual describes it.

Every output is an 11-byte packet: 0x55, a type byte, four little-endian int16 values and a
checksum, the low byte of the sum of the ten bytes before it. Types and scaling (the manual;
the same in the published ``witmotion`` reader, protocol.py):

====  ==================  ====================================================
0x51  acceleration        raw / 32768 · 16 g (g = 9.8 m/s²), then temperature /100 °C
0x52  angular velocity    raw / 32768 · 2000 °/s, then temperature /100 °C
0x53  angle               roll, pitch, yaw raw / 32768 · 180°, then the firmware version
0x59  quaternion          q0 (scalar), q1, q2, q3 raw / 32768
====  ==================  ====================================================

A value past a field's range is clipped there, as the sensor saturates; every value is
rounded to its field's step (the quantisation a reader sees).
"""

from __future__ import annotations

import math
import struct
import numpy as np

from hil.protocols.imu import ImuReading, ImuSample, euler_angles, raw, reading_of

HEADER = 0x55
ACCELERATION = 0x51
ANGULAR_VELOCITY = 0x52
ANGLE = 0x53
QUATERNION = 0x59
#: the packet types hil sends, by their names in a bus config's ``outputs``
OUTPUTS = {"acceleration": ACCELERATION, "angular_velocity": ANGULAR_VELOCITY,
           "angle": ANGLE, "quaternion": QUATERNION}
PACKET_BYTES = 11
#: the manual's g, which its scaling uses (not the standard 9.80665)
G = 9.8
ACCELERATION_RANGE = 16 * G                  # m/s²
ANGULAR_VELOCITY_RANGE = math.radians(2000)  # rad/s
#: the output rates the RATE register offers (Hz; the manual's table, 0.2 Hz to 200 Hz)
RATES_HZ = (0.2, 0.5, 1, 2, 5, 10, 20, 50, 100, 125, 200)
#: the baud rates the BAUD register offers
BAUD_RATES = (4800, 9600, 19200, 38400, 57600, 115200, 230400, 460800, 921600)
#: a UART byte on the wire: start bit, 8 data bits, stop bit
BITS_PER_BYTE = 10
#: the firmware version an angle packet carries (hil's own number: the manual leaves it to
#: the firmware)
VERSION = 1
#: the temperature the packets carry (°C): hil models no thermal drift
TEMPERATURE = 25.0


def packet(kind: int, values: tuple[int, int, int, int]) -> bytes:
    """One packet of ``kind`` carrying four raw int16 values."""
    body = struct.pack("<BB4h", HEADER, kind, *values)
    return body + bytes((sum(body) & 0xFF,))


def _raw(values, full_scale: float) -> list[int]:
    """Values (floats) as the int16 of a field whose +32768 is ``full_scale``: rounded,
    clipped."""
    return raw(values, full_scale / 32768.0)


def encode(sample: ImuSample, outputs: tuple[int, ...]) -> bytes:
    """The packets of one sample, of the types in ``outputs``, in that order."""
    temperature = int(round(TEMPERATURE * 100))
    out = []
    for kind in outputs:
        if kind == ACCELERATION:
            out.append(packet(kind, (*_raw(sample.acceleration.tolist(), ACCELERATION_RANGE),
                                     temperature)))
        elif kind == ANGULAR_VELOCITY:
            out.append(packet(kind, (*_raw(sample.angular_velocity.tolist(),
                                           ANGULAR_VELOCITY_RANGE), temperature)))
        elif kind == ANGLE:
            out.append(packet(kind, (*_raw(euler_angles(sample.orientation), math.pi),
                                     VERSION)))
        elif kind == QUATERNION:
            q = sample.orientation if sample.orientation[0] >= 0 else -sample.orientation
            out.append(packet(kind, tuple(_raw(q.tolist(), 1.0))))
        else:
            raise ValueError(f"no WIT packet type 0x{kind:02X}")
    return b"".join(out)


def orientation_step(outputs: tuple[int, ...]) -> float:
    """The angle (rad) one count of the orientation a reader takes stands for: the
    quaternion's (a part's step moves the angle about twice as far) where it is sent, else
    the angle packet's."""
    return 2 / 32768 if QUATERNION in outputs else math.pi / 32768


def bits_per_second(rate_hz: float, outputs: tuple[int, ...]) -> float:
    """What a sample stream takes of the serial line (bit/s)."""
    return rate_hz * len(outputs) * PACKET_BYTES * BITS_PER_BYTE


class PacketReader:
    """A byte stream's samples: packets found by their 0x55 header and checked by their
    checksum (a bad one is counted and skipped, as the maker's sample code does), a sample
    complete when the last of ``outputs`` arrives."""

    def __init__(self, outputs: tuple[int, ...]):
        self._last = outputs[-1]
        self._buffer = bytearray()
        self._fields: dict[int, tuple[int, ...]] = {}
        self.bad_packets = 0

    def feed(self, data: bytes) -> list[ImuReading]:
        """The samples ``data`` completes (with what came before it)."""
        buffer = self._buffer
        buffer += data
        samples = []
        start = 0
        while len(buffer) - start >= PACKET_BYTES:
            if buffer[start] != HEADER:
                start += 1
                continue
            packet = buffer[start:start + PACKET_BYTES]
            if sum(packet[:10]) & 0xFF != packet[10] or packet[1] not in OUTPUTS.values():
                self.bad_packets += 1
                start += 1                  # resynchronise on the next header
                continue
            self._fields[packet[1]] = struct.unpack_from("<4h", packet, 2)
            start += PACKET_BYTES
            if packet[1] == self._last:
                samples.append(self._sample())
        del buffer[:start]
        return samples

    def _sample(self) -> ImuReading:
        fields, self._fields = self._fields, {}

        def scaled(kind: int, full_scale: float, count: int = 3) -> np.ndarray | None:
            if kind not in fields:
                return None
            return np.array(fields[kind][:count]) / 32768.0 * full_scale

        return reading_of(scaled(ACCELERATION, ACCELERATION_RANGE),
                          scaled(ANGULAR_VELOCITY, ANGULAR_VELOCITY_RANGE),
                          scaled(QUATERNION, 1.0, 4), scaled(ANGLE, math.pi))
