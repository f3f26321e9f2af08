"""Gains of a drive's cascade tuned from the inertia it moves."""

from __future__ import annotations

import math

from hil.errors import HilError, error


def tuned_gains(motor_inertia: float, velocity_bandwidth_hz: float,
                drive: str = "a drive") -> tuple[float, float, float]:
    """(position_kp 1/s, velocity_kp N·m·s/rad, velocity_ki N·m/rad) for the motor-side
    inertia ``motor_inertia`` (kg·m²): velocity-loop bandwidth w = 2*pi*bandwidth,
    Kv = J w, Ki = Kv w / 4, position-loop gain w / 4.

    An inertia that is not finite and positive (a motor the robot's contacts hold still,
    :meth:`hil.plant.Plant.motor_inertias`) gives no gains: HilError naming ``drive``
    rather than a velocity_kp of inf or NaN, which drives the plant to NaN and the drive's
    feedback past what its joint can reach."""
    if not (math.isfinite(motor_inertia) and motor_inertia > 0.0):
        raise HilError(error(
            f"{drive}: hil cannot tune its loops: the inertia its motor moves comes out "
            f"{motor_inertia:g} kg·m² in the start pose (its joint cannot move there, held "
            "by the robot's contacts with the scene, or moves nothing)",
            hint="give the drive `gains: {position_kp, velocity_kp, velocity_ki}` in the bus "
                 "config, or a start_pose in which the joint is free to move; a wheel's "
                 "joint must be continuous for it to roll"))
    omega = 2 * math.pi * velocity_bandwidth_hz
    velocity_kp = motor_inertia * omega
    return omega / 4, velocity_kp, velocity_kp * omega / 4
