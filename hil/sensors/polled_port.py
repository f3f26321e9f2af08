"""The CAN side of a sensor that answers requests, Damiao's DM-IMU-L1: it holds the latest
sample its sampling wrote and answers each read request of a data register with that
register's frame, as :mod:`hil.protocols.dm_imu` describes the product. Its handler runs in
the bus' delivery, with the simulator's lock held."""

from __future__ import annotations

from hil.bus_config.sensor_types import ImuConfig
from hil.can.frame import Frame
from hil.can.router import FrameRouter
from hil.protocols import dm_imu
from hil.protocols.imu import ImuSample
from hil.sensors.port import Port


class PolledImuPort(Port[ImuSample]):
    """A DM-IMU of the bus config on its bus: answers from its first sample on, until it
    falls silent. A request to another IMU (the manual's requests share 0x6FF) is not its
    own; a malformed one, a write or a request of another register is ignored and counted
    in :attr:`refused` (hil's choice where the manual is silent: it names no error answer)."""

    def __init__(self, config: ImuConfig):
        assert config.node_id is not None and config.master_id is not None
        self._node_id = config.node_id
        self._master_id = config.master_id
        self._firmware = dm_imu.FIRMWARES[config.firmware or dm_imu.DEFAULT_FIRMWARE]
        self._request_id = self._firmware.request_id(self._node_id)
        self.device = f"DM-IMU-L1 {self._node_id} on bus '{config.bus}'"
        self.router: FrameRouter | None = None
        self._latest: ImuSample | None = None
        self.answered = 0
        self.refused = 0

    def attach(self, router: FrameRouter) -> None:
        """On its bus: listen to requests."""
        self.router = router
        router.subscribe(self._request_id, self._on_request)

    def write(self, data: ImuSample) -> None:
        """The sample a request now gets."""
        self._latest = data

    def fall_silent(self) -> None:
        """Answer no more: its firmware has stopped."""
        self._latest = None

    def _on_request(self, frame: Frame) -> None:
        data = frame.data
        if (not self._firmware.long_request and len(data) == 4
                and data[0] | data[1] << 8 != self._node_id):
            return                              # another IMU's, on the shared 0x6FF
        register = dm_imu.requested(frame, self._node_id, self._firmware)
        if register is None:
            self.refused += 1
            return
        # before its first sample (or silent) it has nothing to say: no answer
        if self._latest is None or self.router is None:
            return
        self.router.send(dm_imu.answer(self._latest, register, self._master_id, self._firmware))
        self.answered += 1

    def close(self) -> None:
        """Leave the bus."""
        if self.router is not None:
            self.router.unsubscribe(self._request_id, self._on_request)
            self.router = None
