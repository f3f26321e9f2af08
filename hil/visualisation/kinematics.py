"""Where each link of a robot is, as rerun draws it: every joint's transform at once, for
many times (numpy, not a loop per joint and sample)."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from hil.description import JointType, RobotDescription
from hil.description.rotations import rpy_matrix, rpy_quaternion


class JointPoses:
    """Each joint's transform from its parent link's frame to its child's, at joint values,
    as rerun's URDF loader computes it (the joint's origin, then its axis' rotation or
    slide), for every joint of the robot at once: mimic joints from their leaders, the
    others at zero. Frames are named by link, after ``prefix``."""

    def __init__(self, robot: RobotDescription, prefix: str = ""):
        self._joints = [j for j in robot.joints if j.is_movable]
        self._origins = np.array([rpy_quaternion(j.origin.rpy) for j in self._joints])
        self._turns = np.array([rpy_matrix(j.origin.rpy) for j in self._joints]).reshape(-1, 3, 3)
        self._shifts = np.array([j.origin.xyz for j in self._joints], dtype=float)
        axes = np.array([j.axis for j in self._joints], dtype=float)
        self._axes = axes / np.linalg.norm(axes, axis=1)[:, None]
        self._sliding = np.array([j.type is JointType.PRISMATIC for j in self._joints])
        self._parents = [prefix + j.parent for j in self._joints]
        self._children = [prefix + j.child for j in self._joints]

    def transforms(self, positions: Mapping[str, np.ndarray]):
        """Translations (rows x joints, 3), quaternions (xyzw), parent and child frames: for
        each time (``positions``: joint -> a value a time), every joint's transform."""
        times = len(next(iter(positions.values())))
        values = np.zeros((times, len(self._joints)))
        for k, joint in enumerate(self._joints):
            if joint.name in positions:
                values[:, k] = positions[joint.name]
            elif joint.mimic is not None and joint.mimic.joint in positions:
                values[:, k] = (joint.mimic.multiplier * positions[joint.mimic.joint]
                                + joint.mimic.offset)
        turning = np.where(self._sliding, 0.0, values)
        half = turning[:, :, None] / 2
        motion = np.concatenate((self._axes[None] * np.sin(half), np.cos(half)), axis=2)
        quaternions = _product(np.broadcast_to(self._origins, motion.shape), motion)
        slides = np.where(self._sliding, values, 0.0)[:, :, None] * self._axes[None]
        translations = self._shifts[None] + np.einsum("jab,tjb->tja", self._turns, slides)
        return (translations.reshape(-1, 3), quaternions.reshape(-1, 4),
                self._parents * times, self._children * times)


def _product(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton products of quaternions (x, y, z, w), over the last axis."""
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack((aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw,
                     aw * bw - ax * bx - ay * by - az * bz), axis=-1)
