"""Every control cycle in a recording: a row of ``cycle`` per cycle, each signal a column
of 4-byte floats in :class:`~hil.visualisation.blueprint.CycleSeries`' order (why one
entity and 4 bytes: the recorder's module doc)."""

from __future__ import annotations

import numpy as np
import rerun as rr

from hil.messaging.samples import ControlSamples
from hil.visualisation.blueprint import CycleSeries
from hil.visualisation.columns import ScalarTable, Times
from hil.visualisation.entities import RobotEntities


class CycleRows:
    """A batch's cycles as the rows of ``cycle``: per driven joint its reference, measured
    position, error, reference velocity, measured velocity and effort; per drive its motor
    torque; the loop's period and round trip (ms)."""

    def __init__(self, entities: RobotEntities, series: CycleSeries):
        self._entities = entities
        self.series = series
        self._columns: dict[tuple, tuple[np.ndarray, np.ndarray]] = {}   # a batch's layout

    def log_static(self) -> None:
        entities = self._entities
        entities.recording.log(f"{entities.root}/cycle",
                               rr.SeriesLines(names=self.series.names()), static=True)

    def log(self, batch: ControlSamples, times: Times) -> None:
        table = ScalarTable(times)
        table.add_rows(f"{self._entities.root}/cycle", self._rows(batch))
        table.send(self._entities.recording)

    def _rows(self, batch: ControlSamples) -> np.ndarray:
        """The batch's cycles as the rows of ``cycle`` (float32, CycleSeries' order)."""
        layout = (batch.joint_names, batch.actuator_names)
        columns = self._columns.get(layout)
        if columns is None:          # where each joint's and actuator's column of the batch goes
            joints = [batch.joint_names.index(j) for j in self.series.joints]
            actuators = [batch.actuator_names.index(a) for a in self.series.actuators]
            columns = self._columns[layout] = (np.array(joints), np.array(actuators))
        joints, actuators = columns
        reference, position = batch.reference[:, joints], batch.position[:, joints]
        per_joint = np.stack((reference, position, reference - position,
                              batch.reference_velocity[:, joints], batch.velocity[:, joints],
                              batch.effort[:, joints]), axis=2).reshape(len(batch), -1)
        return np.hstack((per_joint, batch.motor_torque[:, actuators],
                          1e3 * batch.cycle_period[:, None],
                          1e3 * batch.round_trip[:, None])).astype(np.float32)
