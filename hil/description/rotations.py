"""URDF's roll-pitch-yaw, the one place it becomes a rotation (the plant's MuJoCo model takes
MuJoCo's own conversion, ``mju_euler2Quat``)."""

from __future__ import annotations

import math

#: a rotation matrix, row by row
Matrix = tuple[float, float, float, float, float, float, float, float, float]


def rpy_matrix(rpy) -> Matrix:
    """Roll-pitch-yaw (fixed axes X, Y, Z) as a rotation matrix, row by row:
    Rz(yaw) Ry(pitch) Rx(roll) (URDF's convention)."""
    cr, sr = math.cos(rpy[0]), math.sin(rpy[0])
    cp, sp = math.cos(rpy[1]), math.sin(rpy[1])
    cy, sy = math.cos(rpy[2]), math.sin(rpy[2])
    return (cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr,
            sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr,
            -sp, cp * sr, cp * cr)


def rpy_quaternion(rpy) -> tuple[float, float, float, float]:
    """Roll-pitch-yaw (fixed axes X, Y, Z) as a unit quaternion x, y, z, w (rerun's order)."""
    cr, sr = math.cos(rpy[0] / 2), math.sin(rpy[0] / 2)
    cp, sp = math.cos(rpy[1] / 2), math.sin(rpy[1] / 2)
    cy, sy = math.cos(rpy[2] / 2), math.sin(rpy[2] / 2)
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy)
