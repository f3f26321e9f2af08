"""DifferentialTransmission: two actuators drive two joints through a differential."""

from __future__ import annotations

import numpy as np

from hil.transmissions.base import CoupledTransmission


class DifferentialTransmission(CoupledTransmission):
    """ros2_control DifferentialTransmission, with actuator reductions ``ar`` and
    joint reductions ``jr``:

    ``a1 = ar1 (jr1 q1 + jr2 q2)``, ``a2 = ar2 (jr1 q1 - jr2 q2)`` (q less offsets);
    ``tau_a1 = (tau_j1/jr1 + tau_j2/jr2) / (2 ar1)``,
    ``tau_a2 = (tau_j1/jr1 - tau_j2/jr2) / (2 ar2)``.
    """

    def _position_matrix(self) -> np.ndarray:
        (ar1, ar2), (jr1, jr2) = self.actuator_reductions, self.joint_reductions
        return np.array([[ar1 * jr1, ar1 * jr2],
                         [ar2 * jr1, -ar2 * jr2]])

    def _effort_matrix(self) -> np.ndarray:
        (ar1, ar2), (jr1, jr2) = self.actuator_reductions, self.joint_reductions
        return np.array([[1 / (2 * ar1 * jr1), 1 / (2 * ar1 * jr2)],
                         [1 / (2 * ar2 * jr1), -1 / (2 * ar2 * jr2)]])
