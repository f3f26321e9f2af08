"""FourBarLinkageTransmission: the second joint's actuator acts across the first."""

from __future__ import annotations

import numpy as np

from hil.transmissions.base import Transmission


class FourBarLinkageTransmission(Transmission):
    """ros2_control FourBarLinkageTransmission:

    ``a1 = ar1 jr1 q1``, ``a2 = ar2 (q1 + jr2 q2)`` (q less offsets);
    ``tau_a1 = tau_j1 / (ar1 jr1)``, ``tau_a2 = (tau_j1 + tau_j2 / jr2) / ar2``.

    Note: ros2_control's effort map is not the transpose of its position map,
    so it does not conserve power; hil reproduces it exactly here, and the
    plant (which must conserve energy) uses the position map's transpose.
    """

    def __init__(self, joints: tuple[str, str], actuators: tuple[str, str],
                 actuator_reductions: tuple[float, float], joint_reductions: tuple[float, float],
                 joint_offsets: tuple[float, float] = (0.0, 0.0)):
        if 0.0 in (*actuator_reductions, *joint_reductions):
            raise ValueError("transmission reduction ratios cannot be zero")
        self.actuator_reductions = tuple(map(float, actuator_reductions))
        self.joint_reductions = tuple(map(float, joint_reductions))
        super().__init__(joints, actuators, joint_offsets)

    def _position_matrix(self) -> np.ndarray:
        (ar1, ar2), (jr1, jr2) = self.actuator_reductions, self.joint_reductions
        return np.array([[ar1 * jr1, 0.0],
                         [ar2, ar2 * jr2]])

    def _effort_matrix(self) -> np.ndarray:
        (ar1, ar2), (jr1, jr2) = self.actuator_reductions, self.joint_reductions
        return np.array([[1 / (ar1 * jr1), 0.0],
                         [1 / ar2, 1 / (ar2 * jr2)]])
