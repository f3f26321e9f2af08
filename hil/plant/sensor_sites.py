"""Sensors in the plant: a site on a link and MuJoCo's own sensors at it, read after each step.

An IMU's: the accelerometer (the specific force in the site's axes: a still sensor reads +g
up, as a real one does), the gyro (angular velocity in its axes) and the framequat (its
orientation in the world). A force-torque sensor's: MuJoCo's force and torque at the site,
what the body the site is on takes from its parent, in the site's axes (the load on a wrist
sensor whose site is on the hand: the hand's and what it holds). They are computed inside
``mj_step`` before it integrates: a reading after a step is of the state that step began
from (one plant step old).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import mujoco
import numpy as np

from hil.description import WORLD, Pose
from hil.plant.shapes import rpy_to_quat


class SensorKind(enum.Enum):
    IMU = "imu"
    FORCE_TORQUE = "force_torque"


#: MuJoCo's sensors of each kind, in the order :meth:`SensorReadings.read` gives them
_SENSORS = {
    SensorKind.IMU: (("accelerometer", mujoco.mjtSensor.mjSENS_ACCELEROMETER, 3),
                     ("gyro", mujoco.mjtSensor.mjSENS_GYRO, 3),
                     ("framequat", mujoco.mjtSensor.mjSENS_FRAMEQUAT, 4)),
    SensorKind.FORCE_TORQUE: (("force", mujoco.mjtSensor.mjSENS_FORCE, 3),
                              ("torque", mujoco.mjtSensor.mjSENS_TORQUE, 3)),
}


@dataclass(frozen=True)
class SensorSite:
    """Where a sensor sits: on ``link``, at ``pose`` in the link's frame."""

    name: str
    link: str
    pose: Pose = Pose()
    kind: SensorKind = SensorKind.IMU


def _site(name: str) -> str:
    return f"hil_sensor_{name}"


def add_sensor_sites(spec: mujoco.MjSpec, sites: tuple[SensorSite, ...]) -> None:
    """A site per sensor and MuJoCo's sensors of its kind at it."""
    for sensor in sites:
        body = spec.worldbody if sensor.link == WORLD else spec.body(sensor.link)
        site = body.add_site(name=_site(sensor.name), pos=sensor.pose.xyz,
                             quat=rpy_to_quat(sensor.pose.rpy))
        for suffix, kind, _ in _SENSORS[sensor.kind]:
            spec.add_sensor(name=f"{site.name}_{suffix}", type=kind,
                            objtype=mujoco.mjtObj.mjOBJ_SITE, objname=site.name)


class SensorReadings:
    """The sensors' values in a model's sensor data."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData,
                 sites: tuple[SensorSite, ...]):
        self._data = data
        self._slices = {}
        for sensor in sites:
            self._slices[sensor.name] = [
                slice(start, start + size) for start, size in (
                    (int(model.sensor(f"{_site(sensor.name)}_{suffix}").adr[0]), size)
                    for suffix, _, size in _SENSORS[sensor.kind])]

    def read(self, name: str) -> tuple[np.ndarray, ...]:
        """The sensor's values, copies: an IMU's specific force (m/s²) and angular velocity
        (rad/s) in its axes and its orientation in the world (w, x, y, z); a force-torque
        sensor's force (N) and torque (N·m) in its axes."""
        data = self._data.sensordata
        return tuple(data[s].copy() for s in self._slices[name])
