"""FourBarLinkageTransmission: the second joint's actuator acts across the first."""

from __future__ import annotations

import numpy as np

from hil.transmissions.base import CoupledTransmission


class FourBarLinkageTransmission(CoupledTransmission):
    """ros2_control FourBarLinkageTransmission:

    ``a1 = ar1 jr1 q1``, ``a2 = ar2 (q1 + jr2 q2)`` (q less offsets);
    ``tau_a1 = tau_j1 / (ar1 jr1)``, ``tau_a2 = (tau_j1 + tau_j2 / jr2) / ar2``.

    Note: ros2_control's effort map is not the transpose of its position map,
    so it does not conserve power; hil reproduces it exactly here, and the
    plant (which must conserve energy) uses the position map's transpose.
    """

    def _position_matrix(self) -> np.ndarray:
        (ar1, ar2), (jr1, jr2) = self.actuator_reductions, self.joint_reductions
        return np.array([[ar1 * jr1, 0.0],
                         [ar2, ar2 * jr2]])

    def _effort_matrix(self) -> np.ndarray:
        (ar1, ar2), (jr1, jr2) = self.actuator_reductions, self.joint_reductions
        return np.array([[1 / (ar1 * jr1), 0.0],
                         [1 / ar2, 1 / (ar2 * jr2)]])
