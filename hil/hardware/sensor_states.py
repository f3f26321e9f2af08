"""What the hardware interface gives the control loop of its sensors: a sample as the
controller received it (:class:`ImuState`, :class:`WrenchState`), and what it says of an IMU
before its first sample (:class:`ImuDescription`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hil.bus_config.sensor_types import ImuConfig
from hil.protocols.imu import ImuReading


@dataclass(frozen=True)
class ImuDescription:
    """What a controller publishes of an IMU before its first sample: its name, the link it
    is on (sensor_msgs' frame_id) and the variance of one sample of its orientation (rad²),
    angular velocity ((rad/s)²) and linear acceleration ((m/s²)²) on each axis."""

    name: str
    frame: str
    variances: tuple[float, float, float]

    @classmethod
    def of(cls, config: ImuConfig) -> ImuDescription:
        """From the sensor's config: its white noise at its rate, its orientation field's
        step (hil models no attitude filter: the angle is the plant's, rounded to the
        field)."""
        return cls(config.name, config.link, (
            config.orientation_step ** 2 / 12,
            config.gyroscope.noise_density ** 2 * config.rate_hz,
            config.accelerometer.noise_density ** 2 * config.rate_hz))


@dataclass(frozen=True)
class ImuState:
    """A sensor's sample as the controller received it."""

    sensor: str
    frame: str                      # the link it is on (sensor_msgs' frame_id)
    received: float                 # wall time (s)
    reading: ImuReading


@dataclass(frozen=True)
class WrenchState:
    """A force-torque sensor's sample as the controller received it."""

    sensor: str
    frame: str                      # the link it is on (geometry_msgs' frame_id)
    received: float                 # wall time (s)
    force: np.ndarray               # N, in its axes
    torque: np.ndarray              # N·m
