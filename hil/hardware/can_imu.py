"""The controller's side of a CAN IMU: its TPDOs taken off its bus' router as they arrive
(in the router's thread), decoded as the maker's parser decodes them, and handed to the
control loop at its next cycle."""

from __future__ import annotations

import time
from collections import deque

from hil.bus_config.sensor_types import ImuConfig
from hil.can.frame import Frame
from hil.can.router import FrameRouter
from hil.hardware.serial_imu import ImuState
from hil.protocols import hipnuc

#: samples kept for the loop: a second's at the fastest rate (a loop that stops reading
#: loses the oldest, never grows memory)
KEEP = 256


class CanImu:
    """One CAN IMU of the bus config, read off its bus once :meth:`attach` ed."""

    def __init__(self, config: ImuConfig, clock=time.time):
        self.config = config
        self._clock = clock
        self._reader = hipnuc.FrameReader(config.node_id, config.outputs)
        self._arrived: deque[ImuState] = deque(maxlen=KEEP)
        self._router: FrameRouter | None = None
        #: why it is not read now (None: it is)
        self.problem: str | None = "its bus is not open yet"

    @property
    def attached(self) -> bool:
        return self._router is not None

    def attach(self, router: FrameRouter) -> None:
        """Listen to its TPDOs on ``router`` (its bus')."""
        self._router = router
        for identifier in self._reader.identifiers:
            router.subscribe(identifier, self._on_frame)
        self.problem = None

    def _on_frame(self, frame: Frame) -> None:
        reading = self._reader.feed(frame)
        if reading is not None:
            self._arrived.append(ImuState(self.config.name, self.config.link, self._clock(),
                                          reading))

    def poll(self) -> list[ImuState]:
        """The samples that arrived since the last call."""
        states = []
        while self._arrived:
            states.append(self._arrived.popleft())
        return states

    def close(self) -> None:
        """Stop listening."""
        if self._router is not None:
            for identifier in self._reader.identifiers:
                self._router.unsubscribe(identifier, self._on_frame)
            self._router = None
