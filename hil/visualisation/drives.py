"""A robot's drives in a recording: each drive's state, on change
(``drives/<actuator>/state``), and its peak torque both ways (``drives/limits``, a row
every LIMITS_EVERY s, which the effort views draw)."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import rerun as rr

from hil.messaging.samples import ControlSamples
from hil.visualisation.columns import ScalarTable, Times
from hil.visualisation.entities import RobotEntities

#: each drive's peak torque is logged this often (s): a line needs no more
LIMITS_EVERY = 1.0


class DriveStates:
    """Each drive's state (StateChange), a row where it changes."""

    def __init__(self, entities: RobotEntities):
        self._entities = entities
        self._last: dict[str, str] = {}

    def restart(self) -> None:
        """A segment's start: each drive's state is logged anew with the next batch."""
        self._last.clear()

    def log(self, batch: ControlSamples, times: Times) -> None:
        for column, actuator in enumerate(batch.actuator_names):
            codes = batch.drive_state[:, column]
            if not len(codes):
                continue
            rows = np.flatnonzero(np.diff(codes)) + 1
            if batch.state_names[codes[0]] != self._last.get(actuator):
                rows = np.concatenate(([0], rows))
            self._last[actuator] = batch.state_names[codes[-1]]
            if len(rows):
                self._entities.recording.send_columns(
                    f"{self._entities.root}/drives/{actuator}/state",
                    indexes=times.columns(rows),
                    columns=rr.StateChange.columns(
                        state=[batch.state_names[c] for c in codes[rows]]))


class TorqueLimits:
    """Each drive's peak torque (by actuator, N·m), both ways, as a line beside its torque."""

    def __init__(self, entities: RobotEntities, limits: Mapping[str, float]):
        self._entities = entities
        self.limits = dict(limits)
        self._logged = -np.inf

    def log_static(self) -> None:
        self._logged = -np.inf
        if self.limits:
            self._entities.recording.log(f"{self._entities.root}/drives/limits", rr.SeriesLines(
                names=[f"{actuator} {sign}peak [N·m]" for actuator in self.limits
                       for sign in "+-"]), static=True)

    def log(self, times: Times) -> None:
        """A row every LIMITS_EVERY s (at the batch's first cycle): a line beside its torque,
        at the bytes of a few rows a minute."""
        if not self.limits or times.wall[0] - self._logged < LIMITS_EVERY:
            return
        self._logged = times.wall[0]
        table = ScalarTable(times.at(np.array([0])))
        table.add_rows(f"{self._entities.root}/drives/limits", np.array(
            [[sign * limit for limit in self.limits.values() for sign in (1, -1)]],
            dtype=np.float32))
        table.send(self._entities.recording)
