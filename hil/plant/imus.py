"""IMUs in the plant: a site on a link and MuJoCo's own sensors at it, read after each step.

MuJoCo's accelerometer gives the specific force in the site's axes (a still sensor reads
+g up, as a real one does), its gyro the angular velocity in the site's axes and its
framequat the site's orientation in the world. They are computed inside ``mj_step`` before it
integrates: a reading after a step is of the state that step began from (one plant step old).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from hil.description import WORLD, Pose
from hil.plant.shapes import rpy_to_quat

#: MuJoCo's sensors of an IMU, in the order :meth:`ImuReadings.read` gives them
_SENSORS = (("accelerometer", mujoco.mjtSensor.mjSENS_ACCELEROMETER),
            ("gyro", mujoco.mjtSensor.mjSENS_GYRO),
            ("framequat", mujoco.mjtSensor.mjSENS_FRAMEQUAT))


@dataclass(frozen=True)
class ImuMount:
    """Where an IMU sits: on ``link``, at ``pose`` in the link's frame."""

    name: str
    link: str
    pose: Pose = Pose()


def _site(name: str) -> str:
    return f"hil_imu_{name}"


def add_imus(spec: mujoco.MjSpec, mounts: tuple[ImuMount, ...]) -> None:
    """A site per mount and its accelerometer, gyro and framequat sensors."""
    for mount in mounts:
        body = spec.worldbody if mount.link == WORLD else spec.body(mount.link)
        site = body.add_site(name=_site(mount.name), pos=mount.pose.xyz,
                             quat=rpy_to_quat(mount.pose.rpy))
        for suffix, kind in _SENSORS:
            spec.add_sensor(name=f"{site.name}_{suffix}", type=kind,
                            objtype=mujoco.mjtObj.mjOBJ_SITE, objname=site.name)


class ImuReadings:
    """The IMUs' values in a model's sensor data."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData,
                 mounts: tuple[ImuMount, ...]):
        self._data = data
        self._slices = {}
        for mount in mounts:
            starts = [int(model.sensor(f"{_site(mount.name)}_{suffix}").adr[0])
                      for suffix, _ in _SENSORS]
            self._slices[mount.name] = [slice(start, start + size) for start, size
                                        in zip(starts, (3, 3, 4))]

    def read(self, name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The IMU's specific force (m/s²) and angular velocity (rad/s) in its axes, and its
        orientation in the world (w, x, y, z), copies."""
        data = self._data.sensordata
        acceleration, rate, orientation = (data[s].copy() for s in self._slices[name])
        return acceleration, rate, orientation
