"""The controller's side of a Net F/T: hil control as its master, requesting long data every
few cycles (the sensor answers requests only) and taking the four answers off its bus'
router as they come, decoded as the manual lays them out; the loop gets them at its next
cycle (:class:`~hil.hardware.bus_sensor.BusSensor`)."""

from __future__ import annotations

import struct
import time

import numpy as np

from hil.bus_config.sensor_types import ForceTorqueConfig
from hil.can.frame import Frame
from hil.hardware.bus_sensor import BusSensor
from hil.hardware.sensor_states import WrenchState
from hil.protocols import ati_netft

class CanForceTorque(BusSensor[WrenchState]):
    """One Net F/T of the bus config, asked for long data every ``every`` cycles once
    attached."""

    def __init__(self, config: ForceTorqueConfig, every: int, clock=time.time):
        super().__init__(tuple(config.base_id + n for n in ati_netft.LONG_ANSWERS),
                         (Frame(config.base_id, bytes((ati_netft.LONG,))),), every)
        self.config = config
        self._clock = clock
        self._parts: dict[int, tuple[int, int]] = {}

    def on_frame(self, frame: Frame) -> None:
        if len(frame.data) != 8:
            return
        self._parts[frame.identifier - self.config.base_id] = struct.unpack("<ii", frame.data)
        if frame.identifier != self.identifiers[-1] or len(self._parts) < 4:
            return
        parts, self._parts = self._parts, {}
        config = self.config
        self.arrived(WrenchState(
            config.name, config.link, self._clock(),
            np.array([parts[n][0] for n in (1, 2, 3)]) / config.counts_per_force,
            np.array([parts[n][1] for n in (1, 2, 3)]) / config.counts_per_torque))
