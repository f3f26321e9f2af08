"""Sensor samples as the controller publishes them, decoded for their readers (the
visualiser): sensor_msgs/Imu on ``hil/<robot>/sensors/<name>/imu``,
geometry_msgs/WrenchStamped on ``.../wrench``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hil.messaging import cdr
from hil.messaging.keys import IMU, WRENCH


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
        name = _sensor_of(key_expr, IMU, "IMU")
        message = cdr.decode(payload, cdr.IMU)

        def field(values, covariance) -> np.ndarray:
            return np.full(len(values), np.nan) if covariance[0] == -1 else np.array(values)

        q = message.orientation
        return cls(name, cdr.seconds_of(message.header.stamp),
                   field((q.w, q.x, q.y, q.z), message.orientation_covariance),
                   field(_xyz(message.angular_velocity), message.angular_velocity_covariance),
                   field(_xyz(message.linear_acceleration),
                         message.linear_acceleration_covariance))


def _sensor_of(key_expr: str, kind: str, what: str) -> str:
    """The sensor's name in its key (``.../sensors/<name>/<kind>``); ValueError if it is none
    of that kind."""
    parts = key_expr.split("/")
    if len(parts) < 3 or parts[-3] != "sensors" or parts[-1] != kind:
        raise ValueError(f"{key_expr} is no {what}'s key")
    return parts[-2]


def _xyz(vector) -> tuple[float, float, float]:
    return (vector.x, vector.y, vector.z)


@dataclass(frozen=True)
class WrenchMessage:
    """One force-torque sample."""

    sensor: str
    stamp: float                     # s (the controller's wall clock at its arrival)
    force: np.ndarray                # N, in the sensor's axes
    torque: np.ndarray               # N·m

    @classmethod
    def decode(cls, key_expr: str, payload: bytes) -> WrenchMessage:
        """From its key (``.../sensors/<name>/wrench``) and CDR; ValueError if malformed."""
        name = _sensor_of(key_expr, WRENCH, "force-torque sensor")
        message = cdr.decode(payload, cdr.WRENCH_STAMPED)
        return cls(name, cdr.seconds_of(message.header.stamp),
                   np.array(_xyz(message.wrench.force)), np.array(_xyz(message.wrench.torque)))
