"""The sensors' samples in a recording, as the controller published them, under
``sensors/<name>``: an IMU's angular velocity, linear acceleration and orientation (roll,
pitch, yaw), a force-torque sensor's force and torque; on the wall and sim timelines of
their arrival."""

from __future__ import annotations

import math

import numpy as np
import rerun as rr

from hil.messaging.keys import IMU, WRENCH
from hil.messaging.sensors import ImuMessage, WrenchMessage
from hil.protocols.imu import euler_angles
from hil.visualisation.columns import ScalarTable
from hil.visualisation.entities import RobotEntities

XYZ = ("x", "y", "z")
#: what a sensor's plots show, by its kind: entity under sensors/<name>, series, unit
QUANTITIES = {
    IMU: (("angular_velocity", XYZ, "rad/s"), ("linear_acceleration", XYZ, "m/s²"),
          ("angles", ("roll", "pitch", "yaw"), "°")),
    WRENCH: (("force", XYZ, "N"), ("torque", XYZ, "N·m")),
}
#: samples gathered before they are sent as one chunk per entity (a 200 Hz IMU: 4 a second)
BATCH = 50


def _rows(messages: list, kind: str) -> list[np.ndarray]:
    """Each quantity's rows (samples x series) of a sensor's messages, in QUANTITIES' order."""
    if kind == WRENCH:
        return [np.array([m.force for m in messages]), np.array([m.torque for m in messages])]
    angles = [[math.degrees(a) for a in euler_angles(m.orientation)]
              if not np.isnan(m.orientation).any() else [math.nan] * 3 for m in messages]
    return [np.array([m.angular_velocity for m in messages]),
            np.array([m.linear_acceleration for m in messages]), np.array(angles)]


class SensorLog:
    """The sensors of ``sensors`` ((name, kind) each); samples of others are counted, not
    drawn."""

    def __init__(self, entities: RobotEntities, sensors: tuple[tuple[str, str], ...]):
        self._entities = entities
        self._kinds = dict(sensors)
        self._pending: dict[str, list[ImuMessage | WrenchMessage]] = {
            name: [] for name in self._kinds}
        self.unknown = 0

    @property
    def sensors(self) -> tuple[tuple[str, str], ...]:
        return tuple(self._kinds.items())

    def entity(self, sensor: str, quantity: str) -> str:
        return f"{self._entities.root}/sensors/{sensor}/{quantity}"

    def log_static(self) -> None:
        for sensor, kind in self._kinds.items():
            for quantity, series, unit in QUANTITIES[kind]:
                self._entities.recording.log(
                    self.entity(sensor, quantity),
                    rr.SeriesLines(names=[f"{s} [{unit}]" for s in series]), static=True)

    def log(self, message: ImuMessage | WrenchMessage) -> None:
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
        kind = self._kinds[sensor]
        table = ScalarTable(self._entities.times(np.array([m.stamp for m in messages])))
        for (quantity, _, _), rows in zip(QUANTITIES[kind], _rows(messages, kind)):
            table.add_rows(self.entity(sensor, quantity), rows)
        table.send(self._entities.recording)
