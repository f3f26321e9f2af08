"""Gains of a drive's cascade tuned from the inertia it moves."""

from __future__ import annotations

import math


def tuned_gains(motor_inertia: float, velocity_bandwidth_hz: float) -> tuple[float, float, float]:
    """(position_kp 1/s, velocity_kp N·m·s/rad, velocity_ki N·m/rad) for the motor-side
    inertia ``motor_inertia`` (kg·m²): velocity-loop bandwidth w = 2*pi*bandwidth,
    Kv = J w, Ki = Kv w / 4, position-loop gain w / 4."""
    omega = 2 * math.pi * velocity_bandwidth_hz
    velocity_kp = motor_inertia * omega
    return omega / 4, velocity_kp, velocity_kp * omega / 4
