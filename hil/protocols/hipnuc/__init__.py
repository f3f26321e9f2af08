"""HiPNUC IMUs on CAN in their CANopen mode (HI12, HI14 and the CH0x0 CAN modules; Roboparty's
RP1 reads one), as the maker's own reader decodes them (github.com/hipnuc/products:
drivers/canopen_parser.c, examples/CAN/dbc/CANopen.dbc).

Each output is a TPDO at its base plus the node id (8 by default), little-endian int16s:

=========  =======  ===  ===================================================
TPDO1      0x180+n  6 B  acceleration x, y, z in 0.001 g (the reader's g: 9.81 m/s²)
TPDO2      0x280+n  6 B  angular rate x, y, z in 0.1 °/s
TPDO3      0x380+n  6 B  roll, pitch, yaw in 0.01 °
TPDO4      0x480+n  8 B  quaternion w, x, y, z in 0.0001
=========  =======  ===  ===================================================

The maker's code sends nothing to start the device (its readers only listen) and reads it
at 500 kbit/s. The NMT behaviour is hil's reading of that and of CiA 301 (the maker's
documents are silent): a boot-up at power-on, then operational on its own; NMT stop and
pre-operational silence its TPDOs, start brings them back, a reset boots it again.
"""

from __future__ import annotations

import math
import struct

import numpy as np

from hil.can.frame import Frame, FrameSpec
from hil.protocols.imu import ImuReading, ImuSample, euler_angles, raw, reading_of

ACCELERATION = 0x180
ANGULAR_VELOCITY = 0x280
ANGLE = 0x380
QUATERNION = 0x480
#: the TPDOs by the names a bus config's ``outputs`` give, in the maker's order
OUTPUTS = {"acceleration": ACCELERATION, "angular_velocity": ANGULAR_VELOCITY,
           "angle": ANGLE, "quaternion": QUATERNION}
TPDO_NAMES = {ACCELERATION: "TPDO1", ANGULAR_VELOCITY: "TPDO2", ANGLE: "TPDO3",
              QUATERNION: "TPDO4"}
LENGTHS = {ACCELERATION: 6, ANGULAR_VELOCITY: 6, ANGLE: 6, QUATERNION: 8}
DEFAULT_NODE_ID = 8
#: the maker's reader's g (canopen_parser.c), which its scaling uses
G = 9.81
ACCELERATION_STEP = 0.001 * G                  # m/s² per count
ANGULAR_VELOCITY_STEP = math.radians(0.1)      # rad/s per count
ANGLE_STEP = math.radians(0.01)                # rad per count
QUATERNION_STEP = 0.0001
#: the fastest output rate hil serves (Hz): hil's bound, the HI12's stated 0-200 Hz as a
#: secondhand note cites HiPNUC's programming manual (the maker's code is silent)
MAX_RATE_HZ = 200.0
#: CANopen's NMT (CiA 301): command frame id, boot-up / heartbeat base
NMT = 0x000
BOOT_UP = 0x700


def orientation_step(outputs: tuple[int, ...]) -> float:
    """The angle (rad) one count of the orientation a reader takes stands for: the
    quaternion's (a part's step moves the angle about twice as far) where it is sent, else
    the angles'."""
    return 2 * QUATERNION_STEP if QUATERNION in outputs else ANGLE_STEP


def frames(sample: ImuSample, node_id: int, outputs: tuple[int, ...]) -> list[Frame]:
    """The TPDOs of one sample, of the kinds in ``outputs``, in that order."""
    out = []
    for kind in outputs:
        if kind == ACCELERATION:
            values = raw(sample.acceleration.tolist(), ACCELERATION_STEP)
        elif kind == ANGULAR_VELOCITY:
            values = raw(sample.angular_velocity.tolist(), ANGULAR_VELOCITY_STEP)
        elif kind == ANGLE:
            values = raw(euler_angles(sample.orientation), ANGLE_STEP)
        elif kind == QUATERNION:
            q = sample.orientation if sample.orientation[0] >= 0 else -sample.orientation
            values = raw(q.tolist(), QUATERNION_STEP)
        else:
            raise ValueError(f"no HiPNUC TPDO 0x{kind:03X}")
        out.append(Frame(kind + node_id, struct.pack(f"<{len(values)}h", *values)))
    return out


def frame_specs(node_id: int, rate_hz: float, outputs: tuple[int, ...],
                what: str) -> list[FrameSpec]:
    """Its frames on the bus: the TPDOs at the sensor's rate and its boot-up (for the bus'
    load and its ids; a replay tells them by these)."""
    return [FrameSpec(kind + node_id, LENGTHS[kind], rate_hz, f"{what} {TPDO_NAMES[kind]}")
            for kind in outputs] + [FrameSpec(BOOT_UP + node_id, 1, 0.0, f"{what} boot-up")]


class FrameReader:
    """A node's TPDOs as samples: one complete when the last of ``outputs`` arrives (a frame
    of the wrong length is counted in :attr:`bad_frames` and skipped)."""

    def __init__(self, node_id: int, outputs: tuple[int, ...]):
        self.identifiers = tuple(kind + node_id for kind in outputs)
        self._node_id = node_id
        self._last = outputs[-1]
        self._fields: dict[int, tuple[int, ...]] = {}
        self.bad_frames = 0

    def feed(self, frame: Frame) -> ImuReading | None:
        """The sample ``frame`` completes, if it does."""
        kind = frame.identifier - self._node_id
        if kind not in LENGTHS or len(frame.data) != LENGTHS[kind]:
            self.bad_frames += 1
            return None
        self._fields[kind] = struct.unpack(f"<{LENGTHS[kind] // 2}h", frame.data)
        if kind != self._last:
            return None
        fields, self._fields = self._fields, {}

        def scaled(kind: int, step: float) -> np.ndarray | None:
            return np.array(fields[kind]) * step if kind in fields else None

        return reading_of(scaled(ACCELERATION, ACCELERATION_STEP),
                          scaled(ANGULAR_VELOCITY, ANGULAR_VELOCITY_STEP),
                          scaled(QUATERNION, QUATERNION_STEP), scaled(ANGLE, ANGLE_STEP))
