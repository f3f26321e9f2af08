"""The CAN side of a CAN sensor: a CANopen node on its bus' router that sends the sensor's
frames while operational and follows NMT (CiA 301 section 7.2.8.3.1), as
:mod:`hil.protocols.hipnuc` describes the product's behaviour."""

from __future__ import annotations

from collections.abc import Sequence

from hil.can.frame import Frame
from hil.can.router import FrameRouter
from hil.protocols import hipnuc
from hil.sensors.port import Port

#: NMT command specifiers (CiA 301)
START, STOP, PRE_OPERATIONAL, RESET_NODE, RESET_COMMUNICATION = 0x01, 0x02, 0x80, 0x81, 0x82


class CanSensorPort(Port[Sequence[Frame]]):
    """Node ``node_id`` on ``bus``: boots (its boot-up frame) when attached to the bus' router
    and is then operational on its own; NMT stop or pre-operational silence it, start brings
    it back, a reset boots it again. A malformed NMT frame is ignored, as CiA 301 has it."""

    def __init__(self, bus: str, node_id: int):
        self.node_id = node_id
        self.device = f"CANopen node {node_id} on bus '{bus}'"
        self.router: FrameRouter | None = None
        self.operational = False
        self.lost_frames = 0           # samples' frames while not operational or unattached

    def attach(self, router: FrameRouter) -> None:
        """On the bus: subscribe to NMT, boot."""
        self.router = router
        router.subscribe(hipnuc.NMT, self._on_nmt)
        self._boot()

    def _boot(self) -> None:
        assert self.router is not None
        self.router.send(Frame(hipnuc.BOOT_UP + self.node_id, b"\x00"))
        self.operational = True

    def _on_nmt(self, frame: Frame) -> None:
        data = frame.data
        if len(data) != 2 or data[1] not in (0, self.node_id):
            return
        command = data[0]
        if command == START:
            self.operational = True
        elif command in (STOP, PRE_OPERATIONAL):
            self.operational = False
        elif command in (RESET_NODE, RESET_COMMUNICATION):
            self._boot()

    def write(self, frames: Sequence[Frame]) -> None:
        """Send a sample's frames, if operational on the bus."""
        if self.router is None or not self.operational:
            self.lost_frames += len(frames)
            return
        self.router.send_frames(frames)

    def close(self) -> None:
        """Leave the bus."""
        if self.router is not None:
            self.router.unsubscribe(hipnuc.NMT, self._on_nmt)
            self.router = None
