"""The controller's side of a CAN IMU, handed to the control loop at its next cycle
(:class:`~hil.hardware.bus_sensor.BusSensor`): a HiPNUC's TPDOs taken off its bus' router
as they arrive, decoded as the maker's parser decodes them (:class:`CanImu`); a DM-IMU
polled, hil control its master, its answers decoded as the maker's manual reads them
(:class:`PolledCanImu`)."""

from __future__ import annotations

import time

from hil.bus_config.sensor_types import ImuConfig
from hil.can.frame import Frame
from hil.hardware.bus_sensor import BusSensor
from hil.hardware.sensor_states import ImuState
from hil.protocols import dm_imu, hipnuc


class _ImuOnBus(BusSensor[ImuState]):
    """An IMU whose frames of ``identifiers`` ``reader`` decodes into samples."""

    def __init__(self, config: ImuConfig, reader: hipnuc.FrameReader | dm_imu.AnswerReader,
                 identifiers: tuple[int, ...], clock, requests: tuple[Frame, ...] = (),
                 every: int = 1):
        super().__init__(identifiers, requests, every)
        self.config = config
        self._reader = reader
        self._clock = clock

    def on_frame(self, frame: Frame) -> None:
        reading = self._reader.feed(frame)
        if reading is not None:
            self.arrived(ImuState(self.config.name, self.config.link, self._clock(), reading))


class CanImu(_ImuOnBus):
    """One CANopen IMU of the bus config, read off its bus once attached."""

    def __init__(self, config: ImuConfig, clock=time.time):
        reader = hipnuc.FrameReader(config.node_id, config.outputs)
        super().__init__(config, reader, reader.identifiers, clock)


class PolledCanImu(_ImuOnBus):
    """One DM-IMU of the bus config: each of its outputs requested every ``every`` cycles
    once attached, a sample complete when the last one's answer comes."""

    def __init__(self, config: ImuConfig, every: int, clock=time.time):
        firmware = dm_imu.FIRMWARES[config.firmware]
        super().__init__(config, dm_imu.AnswerReader(config.outputs, firmware),
                         (config.master_id,), clock,
                         tuple(dm_imu.request(register, config.node_id, firmware)
                               for register in config.outputs), every)
