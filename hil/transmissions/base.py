"""The transmission seam: pure maps between actuator and joint space.

A concrete transmission only states its two linear maps, joint -> actuator,
for position/velocity (``P``) and for effort (``E``), from its reductions;
the base class does the rest (offsets, inverses, every direction). The maps
are those of ros2_control's ``transmission_interface``, so a controller
written against ros2_control sees the same numbers.
"""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np


class Transmission(ABC):
    """Maps position, velocity and effort between actuators and joints.

    Positions: ``a = P (q - offset)`` and ``q = P^-1 a + offset``;
    velocities: ``a' = P q'``; efforts: ``tau_a = E tau_j``.
    Arrays are ordered as ``joints`` and ``actuators``.
    """

    def __init__(self, joints: tuple[str, ...], actuators: tuple[str, ...],
                 joint_offsets: tuple[float, ...]):
        self.joints = tuple(joints)
        self.actuators = tuple(actuators)
        self.joint_offsets = np.asarray(joint_offsets, dtype=float)
        # most transmissions have none: then x - 0 is x, and the maps skip a numpy call
        self._has_offsets = bool(np.count_nonzero(self.joint_offsets))
        self.position_matrix = np.asarray(self._position_matrix(), dtype=float)
        self.effort_matrix = np.asarray(self._effort_matrix(), dtype=float)
        self._position_inverse = np.linalg.inv(self.position_matrix)
        self._effort_inverse = np.linalg.inv(self.effort_matrix)
        # actuator_to_joint_feedback's three maps as one block-diagonal product
        self._feedback_map = _block_diagonal(self._position_inverse, self._position_inverse,
                                             self._effort_inverse)
        self._feedback_offsets = np.concatenate(
            [self.joint_offsets, np.zeros(2 * len(self.joint_offsets))])

    @abstractmethod
    def _position_matrix(self) -> np.ndarray:
        """P: actuator positions (and velocities) from joint ones."""

    @abstractmethod
    def _effort_matrix(self) -> np.ndarray:
        """E: actuator efforts from joint efforts."""

    # the maps by ndarray.dot, not @: numpy's matmul goes through its gufunc machinery, slower
    # than dot on these small maps (a control cycle maps five times), with the same result
    # to the bit (docs/performance.md, "2026-12-01: the in-process cycle in a fifth fewer
    # instructions")
    def joint_to_actuator_position(self, q) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        return self.position_matrix.dot(q - self.joint_offsets if self._has_offsets else q)

    def actuator_to_joint_position(self, a) -> np.ndarray:
        return self._position_inverse.dot(np.asarray(a, dtype=float)) + self.joint_offsets

    def joint_to_actuator_velocity(self, dq) -> np.ndarray:
        return self.position_matrix.dot(np.asarray(dq, dtype=float))

    def actuator_to_joint_velocity(self, da) -> np.ndarray:
        return self._position_inverse.dot(np.asarray(da, dtype=float))

    def joint_to_actuator_effort(self, tau_j) -> np.ndarray:
        return self.effort_matrix.dot(np.asarray(tau_j, dtype=float))

    def actuator_to_joint_effort(self, tau_a) -> np.ndarray:
        return self._effort_inverse.dot(np.asarray(tau_a, dtype=float))

    def actuator_to_joint_feedback(self, measured) -> np.ndarray:
        """Actuator positions, velocities and efforts, one after the other in one array,
        to the joints' in the same layout: the three maps above in one product (a cycle's
        feedback, one numpy call instead of three; the same numbers for finite values)."""
        joint = self._feedback_map.dot(np.asarray(measured, dtype=float))
        return joint + self._feedback_offsets if self._has_offsets else joint

    def actuator_effort_limits(self, joint_efforts) -> np.ndarray:
        """Largest actuator effort needed to reach the joints' effort limits."""
        return np.abs(self.effort_matrix) @ np.abs(np.asarray(joint_efforts, dtype=float))

    def __repr__(self) -> str:
        return f"{type(self).__name__}(joints={self.joints}, actuators={self.actuators})"


class CoupledTransmission(Transmission):
    """Two actuators, two joints, with reductions on both sides (ros2_control's
    ``actuator_reduction`` / ``joint_reduction``); subclasses give the maps."""

    def __init__(self, joints: tuple[str, str], actuators: tuple[str, str],
                 actuator_reductions: tuple[float, float], joint_reductions: tuple[float, float],
                 joint_offsets: tuple[float, float] = (0.0, 0.0)):
        if 0.0 in (*actuator_reductions, *joint_reductions):
            raise ValueError("transmission reduction ratios cannot be zero")
        self.actuator_reductions = tuple(map(float, actuator_reductions))
        self.joint_reductions = tuple(map(float, joint_reductions))
        super().__init__(joints, actuators, joint_offsets)


class TransmissionStack(Transmission):
    """Several transmissions as one block-diagonal map, over arrays in the given joint and
    actuator orders: a whole robot mapped with three matrix products instead of a loop of
    small ones per transmission. The joints and actuators of the parts, each exactly once."""

    def __init__(self, parts: tuple[Transmission, ...], joints: tuple[str, ...],
                 actuators: tuple[str, ...]):
        self.parts = tuple(parts)
        rows = [[actuators.index(name) for name in part.actuators] for part in self.parts]
        columns = [[joints.index(name) for name in part.joints] for part in self.parts]
        if sorted(sum(rows, [])) != list(range(len(actuators))) or \
                sorted(sum(columns, [])) != list(range(len(joints))):
            raise ValueError("each joint and actuator must belong to exactly one transmission")
        self._blocks = list(zip(rows, columns))
        offsets = np.zeros(len(joints))
        for part, columns_of_part in zip(self.parts, columns):
            offsets[columns_of_part] = part.joint_offsets
        super().__init__(joints, actuators, tuple(offsets))

    def _stacked(self, matrix_of) -> np.ndarray:
        result = np.zeros((len(self.actuators), len(self.joints)))
        for part, (rows, columns) in zip(self.parts, self._blocks):
            result[np.ix_(rows, columns)] = matrix_of(part)
        return result

    def _position_matrix(self) -> np.ndarray:
        return self._stacked(lambda part: part.position_matrix)

    def _effort_matrix(self) -> np.ndarray:
        return self._stacked(lambda part: part.effort_matrix)


def _block_diagonal(*blocks: np.ndarray) -> np.ndarray:
    """The square blocks along the diagonal of one matrix, zeros elsewhere (scipy's
    linalg.block_diag; hil does not depend on scipy for this alone)."""
    size = sum(len(block) for block in blocks)
    matrix, at = np.zeros((size, size)), 0
    for block in blocks:
        matrix[at:at + len(block), at:at + len(block)] = block
        at += len(block)
    return matrix
