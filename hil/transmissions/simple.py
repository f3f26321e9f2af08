"""SimpleTransmission: one actuator, one joint, a reduction and an offset."""

from __future__ import annotations

import numpy as np

from hil.transmissions.base import Transmission


class SimpleTransmission(Transmission):
    """``a = n (q - offset)``, ``tau_a = tau_j / n`` (ros2_control SimpleTransmission)."""

    def __init__(self, joint: str, actuator: str, reduction: float, offset: float = 0.0):
        if reduction == 0:
            raise ValueError("transmission reduction ratio cannot be zero")
        self.reduction = float(reduction)
        super().__init__((joint,), (actuator,), (offset,))

    def _position_matrix(self) -> np.ndarray:
        return np.array([[self.reduction]])

    def _effort_matrix(self) -> np.ndarray:
        return np.array([[1.0 / self.reduction]])
