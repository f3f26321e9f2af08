"""What every IMU product's wire carries, whatever its codec: a sample as the device makes it
(:class:`ImuSample`) and as a reader decodes it (:class:`ImuReading`), and the z-y-x Euler
angles the products send (WitMotion's angle packet, HiPNUC's TPDO3)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ImuSample:
    """One output of the IMU, in SI units in the sensor's own axes."""

    acceleration: np.ndarray        # specific force (m/s²): a still sensor reads +g up
    angular_velocity: np.ndarray    # rad/s
    orientation: np.ndarray         # unit quaternion (w, x, y, z), the sensor in the world


@dataclass(frozen=True)
class ImuReading:
    """One sample as a reader decodes it, in SI units; a field the sample's packets did not
    carry is None."""

    acceleration: np.ndarray | None = None
    angular_velocity: np.ndarray | None = None
    orientation: np.ndarray | None = None       # (w, x, y, z)


def euler_angles(quaternion: np.ndarray) -> tuple[float, float, float]:
    """Roll (x), pitch (y), yaw (z) in rad of a (w, x, y, z) quaternion, in the z-y-x order."""
    w, x, y, z = (float(v) for v in quaternion)
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


def quaternion_of(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """The (w, x, y, z) quaternion of z-y-x Euler angles (rad)."""
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return np.array([cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy,
                     cr * sp * cy + sr * cp * sy, cr * cp * sy - sr * sp * cy])


def reading_of(acceleration=None, angular_velocity=None, quaternion=None,
               angles=None) -> ImuReading:
    """A decoded sample from the fields it carries (SI units, None where not sent): its
    orientation from the quaternion (normalised: the field's steps leave it off unit) where it
    carries one, else from its z-y-x angles."""
    orientation = None
    if quaternion is not None:
        orientation = np.asarray(quaternion, dtype=float)
        orientation = orientation / (np.linalg.norm(orientation) or 1.0)
    elif angles is not None:
        orientation = quaternion_of(*angles)
    return ImuReading(acceleration, angular_velocity, orientation)


def raw(values, step: float, bits: int = 16) -> list[int]:
    """Values (Python floats) as the signed integers of a field of ``step`` per count: clipped at the
    field's range (the sensor saturates there), rounded half to even. In Python floats: numpy
    on three values took 11 µs of a sample's 45 (docs/performance.md, "2026-12-06, night: a
    sensor's sample")."""
    top = 1 << (bits - 1)
    return [int(round(max(-top, min(top - 1, v / step)))) for v in values]
