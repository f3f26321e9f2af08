"""The JTC's decelerate_on_cancel stop: each joint from its measured position and velocity
to rest at its own constant deceleration, then held (ros2_controllers,
joint_trajectory_controller/doc/decelerate_on_cancel.rst; decelerate_to_hold_position in
joint_trajectory_controller.cpp, which samples the same curve every update period)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class StopRamp:
    """p(t) = p0 + v0 t - s a t^2 / 2 until t_stop = |v0| / a, then p0 + s v0^2 / (2 a)."""

    start: float                  # controller clock
    p0: np.ndarray
    v0: np.ndarray
    deceleration: np.ndarray      # > 0 per joint

    def sample(self, now: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Position, velocity and acceleration at ``now``."""
        direction = np.where(self.v0 >= 0.0, 1.0, -1.0)
        stop_time = np.abs(self.v0) / self.deceleration
        t = np.minimum(max(now - self.start, 0.0), stop_time)
        moving = t < stop_time
        position = self.p0 + self.v0 * t - 0.5 * direction * self.deceleration * t * t
        velocity = np.where(moving, self.v0 - direction * self.deceleration * t, 0.0)
        acceleration = np.where(moving, -direction * self.deceleration, 0.0)
        return position, velocity, acceleration
