"""Piecewise polynomial joint trajectories, planned for all of a goal's points at once.

A goal of N points becomes N polynomial segments of one order for every joint: linear
(positions only), cubic (with velocities) or quintic (with accelerations), as
ros2_controllers' joint_trajectory_controller interpolates. The segments between points are
planned with numpy for all points together (a 10,000-point goal in milliseconds); only the
first, from the controller's current desired state to point 0, depends on that state, so the
controller plans it last, under its lock (:meth:`Spline.start_from`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: a first point at time 0 where the joints already are: a segment this short holds it
INSTANT = 1e-9
#: tau's powers a sample takes, and the factors of their first and second derivatives (made
#: once: a sample is taken every cycle)
_EXPONENTS = np.arange(6)
_VELOCITY_FACTORS = np.arange(1, 6)
_ACCELERATION_FACTORS = np.array([2, 6, 12, 20])


def coefficients(duration: np.ndarray, p0: np.ndarray, v0: np.ndarray, a0: np.ndarray,
                 p1: np.ndarray, v1: np.ndarray, a1: np.ndarray, order: int) -> np.ndarray:
    """(segments, 6, joints) coefficients c_k of p(tau) = sum c_k tau^k joining (p0, v0, a0)
    at tau = 0 to (p1, v1, a1) at tau = duration, for each segment (rows of the inputs)."""
    T = duration[:, None]
    c = np.zeros((len(duration), 6, p0.shape[1]))
    if order == 1:
        c[:, 0], c[:, 1] = p0, (p1 - p0) / T
    elif order == 3:
        c[:, 0], c[:, 1] = p0, v0
        c[:, 2] = (3 * (p1 - p0) - (2 * v0 + v1) * T) / T ** 2
        c[:, 3] = (2 * (p0 - p1) + (v0 + v1) * T) / T ** 3
    else:
        c[:, 0], c[:, 1], c[:, 2] = p0, v0, a0 / 2
        c[:, 3] = (20 * (p1 - p0) - (8 * v1 + 12 * v0) * T - (3 * a0 - a1) * T ** 2) / (2 * T ** 3)
        c[:, 4] = (30 * (p0 - p1) + (14 * v1 + 16 * v0) * T + (3 * a0 - 2 * a1) * T ** 2) / (
            2 * T ** 4)
        c[:, 5] = (12 * (p1 - p0) - (6 * v1 + 6 * v0) * T - (a0 - a1) * T ** 2) / (2 * T ** 5)
    return c


@dataclass
class Spline:
    """Segments on the goal's own clock (0 = the goal's start): segment s covers
    [t0[s], t1[s]]; segment 0 runs from the controller's state to point 0."""

    t0: np.ndarray               # (segments,)
    t1: np.ndarray               # (segments,)
    coefficients: np.ndarray     # (segments, 6, joints)
    points: np.ndarray           # (segments, joints): the positions each segment ends at
    velocities: np.ndarray
    accelerations: np.ndarray
    order: int

    @classmethod
    def between(cls, times: np.ndarray, positions: np.ndarray, velocities: np.ndarray,
                accelerations: np.ndarray, order: int) -> Spline:
        """The segments between consecutive points (``times`` from the goal's start,
        increasing); segment 0 is left for :meth:`start_from`."""
        t0 = np.concatenate(([0.0], times[:-1]))
        c = np.zeros((len(times), 6, positions.shape[1]))
        if len(times) > 1:
            c[1:] = coefficients(times[1:] - times[:-1], positions[:-1], velocities[:-1],
                                 accelerations[:-1], positions[1:], velocities[1:],
                                 accelerations[1:], order)
        return cls(t0, times.astype(float), c, positions, velocities, accelerations, order)

    def start_from(self, p0: np.ndarray, v0: np.ndarray, a0: np.ndarray,
                   at: float = 0.0) -> None:
        """Plan segment 0, from the controller's state at ``at`` (goal clock: the goal's
        stamp may lie before or after now) to point 0 (the JTC's point before the
        trajectory). A first point due now where the joints already are is held."""
        p1, v1, a1 = self.points[:1], self.velocities[:1], self.accelerations[:1]
        self.t0[0] = at
        if self.t1[0] > at:
            v0 = v0 if self.order > 1 else np.zeros_like(v0)
            self.coefficients[0] = coefficients(self.t1[:1] - at, p0[None], v0[None],
                                                a0[None], p1, v1, a1, self.order)[0]
        else:     # point 0 due now (held), or past (the JTC's jump: a constant, never run)
            if self.t1[0] == at:
                self.t1[0] = at + INSTANT
            self.coefficients[0] = coefficients(np.array([INSTANT]), p1, v1, a1, p1, v1, a1,
                                                1)[0]

    def shift(self, offsets: np.ndarray) -> None:
        """Move every position by ``offsets`` (per joint; whole turns of continuous joints)."""
        if offsets.any():
            self.coefficients[:, 0] += offsets
            self.points += offsets

    @property
    def end(self) -> float:
        return float(self.t1[-1])

    def segment_at(self, t: float) -> int:
        """The segment running at ``t`` (goal clock): the index of the point it runs to
        (0 before the start, the last after the end)."""
        return min(int(np.searchsorted(self.t1, t, side="left")), len(self.t1) - 1)

    def sample(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity and acceleration at ``t`` (goal clock), held at either end."""
        s = self.segment_at(t)
        tau = min(max(t - self.t0[s], 0.0), self.t1[s] - self.t0[s])
        c = self.coefficients[s]
        powers = tau ** _EXPONENTS
        # ndarray.dot, not @ (sampled every cycle; see hil.transmissions.base)
        position = powers.dot(c)
        velocity = (_VELOCITY_FACTORS * powers[:5]).dot(c[1:])
        acceleration = (_ACCELERATION_FACTORS * powers[:4]).dot(c[2:])
        return position, velocity, acceleration
