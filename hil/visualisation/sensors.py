"""The IMUs' samples in a recording, as the controller published them: each sensor's angular
velocity, linear acceleration and orientation (roll, pitch, yaw) under ``sensors/<name>``,
on the wall and sim timelines of their arrival."""

from __future__ import annotations

import math

import numpy as np
import rerun as rr

from hil.messaging.sensors import ImuMessage
from hil.protocols.imu import euler_angles
from hil.visualisation.columns import ScalarTable
from hil.visualisation.entities import RobotEntities

#: what a sensor's plots show: entity under sensors/<name>, its series, its unit
QUANTITIES = (("angular_velocity", ("x", "y", "z"), "rad/s"),
              ("linear_acceleration", ("x", "y", "z"), "m/s²"),
              ("angles", ("roll", "pitch", "yaw"), "°"))
#: samples gathered before they are sent as one chunk per entity (a 200 Hz IMU: 4 a second)
BATCH = 50


class ImuLog:
    """The IMUs named in ``sensors``; samples of others are counted, not drawn."""

    def __init__(self, entities: RobotEntities, sensors: tuple[str, ...]):
        self._entities = entities
        self._pending: dict[str, list[ImuMessage]] = {name: [] for name in sensors}
        self.unknown = 0

    @property
    def sensors(self) -> list[str]:
        return list(self._pending)

    def entity(self, sensor: str, quantity: str) -> str:
        return f"{self._entities.root}/sensors/{sensor}/{quantity}"

    def log_static(self) -> None:
        for sensor in self._pending:
            for quantity, series, unit in QUANTITIES:
                self._entities.recording.log(
                    self.entity(sensor, quantity),
                    rr.SeriesLines(names=[f"{s} [{unit}]" for s in series]), static=True)

    def log(self, message: ImuMessage) -> None:
        pending = self._pending.get(message.sensor)
        if pending is None:
            self.unknown += 1
            return
        pending.append(message)
        if len(pending) >= BATCH:
            self._send(message.sensor)

    def flush(self) -> None:
        for sensor in self._pending:
            self._send(sensor)

    def _send(self, sensor: str) -> None:
        messages, self._pending[sensor] = self._pending[sensor], []
        if not messages:
            return
        table = ScalarTable(self._entities.times(np.array([m.stamp for m in messages])))
        table.add_rows(self.entity(sensor, "angular_velocity"),
                       np.array([m.angular_velocity for m in messages]))
        table.add_rows(self.entity(sensor, "linear_acceleration"),
                       np.array([m.linear_acceleration for m in messages]))
        table.add_rows(self.entity(sensor, "angles"), np.array(
            [[math.degrees(a) for a in euler_angles(m.orientation)]
             if not np.isnan(m.orientation).any() else [math.nan] * 3 for m in messages]))
        table.send(self._entities.recording)
