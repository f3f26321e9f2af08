"""The controller's side of a CAN IMU: its TPDOs taken off its bus' router as they arrive,
decoded as the maker's parser decodes them, and handed to the control loop at its next
cycle (:class:`~hil.hardware.bus_sensor.BusSensor`)."""

from __future__ import annotations

import time

from hil.bus_config.sensor_types import ImuConfig
from hil.can.frame import Frame
from hil.hardware.bus_sensor import BusSensor
from hil.hardware.sensor_states import ImuState
from hil.protocols import hipnuc


class CanImu(BusSensor[ImuState]):
    """One CAN IMU of the bus config, read off its bus once attached."""

    def __init__(self, config: ImuConfig, clock=time.time):
        self._reader = hipnuc.FrameReader(config.node_id, config.outputs)
        super().__init__(self._reader.identifiers)
        self.config = config
        self._clock = clock

    def on_frame(self, frame: Frame) -> None:
        reading = self._reader.feed(frame)
        if reading is not None:
            self.arrived(ImuState(self.config.name, self.config.link, self._clock(), reading))
