"""Sensor samples as the controller publishes them, decoded for their readers (the
visualiser): sensor_msgs/Imu on ``hil/<robot>/sensors/<name>/imu``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hil.messaging import cdr


@dataclass(frozen=True)
class ImuMessage:
    """One IMU sample; a field the sensor did not send is NaN."""

    sensor: str
    stamp: float                     # s (the controller's wall clock at its arrival)
    orientation: np.ndarray          # (w, x, y, z)
    angular_velocity: np.ndarray     # rad/s
    linear_acceleration: np.ndarray  # m/s²

    @classmethod
    def decode(cls, key_expr: str, payload: bytes) -> ImuMessage:
        """From its key (``.../sensors/<name>/imu``) and CDR; ValueError if malformed."""
        parts = key_expr.split("/")
        if len(parts) < 3 or parts[-3] != "sensors" or parts[-1] != "imu":
            raise ValueError(f"{key_expr} is no IMU's key")
        message = cdr.decode(payload, cdr.IMU)

        def field(values, covariance) -> np.ndarray:
            return np.full(len(values), np.nan) if covariance[0] == -1 else np.array(values)

        q = message.orientation
        return cls(parts[-2], cdr.seconds_of(message.header.stamp),
                   field((q.w, q.x, q.y, q.z), message.orientation_covariance),
                   field(_xyz(message.angular_velocity), message.angular_velocity_covariance),
                   field(_xyz(message.linear_acceleration),
                         message.linear_acceleration_covariance))


def _xyz(vector) -> tuple[float, float, float]:
    return (vector.x, vector.y, vector.z)
