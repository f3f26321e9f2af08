"""python canopen on hil's frame router (hil.protocols.cia402.network, issue 66 item 2):
canopen's subscribers hear a router's frames as canopen's own MessageListener hands them
over (COB-ID, a bytearray, the timestamp), what canopen sends is a Frame, identifiers over
0x7FF are 29-bit ones (canopen's Network.send_message), and a drive that leaves its bus
leaves no handler behind."""

from __future__ import annotations

import threading
import uuid

import can

from conftest import TEST_MOTOR_DRIVE
from test_cia402_files import drive_config

from hil.can.frame import Frame
from hil.can.router import FrameRouter
from hil.drives.core import DriveCore
from hil.drives.definitions import DriveParameters
from hil.protocols.cia402.drive import Cia402Drive
from hil.protocols.cia402.network import RoutedNetwork


class SentFrames(FrameRouter):
    """A router on a bus of its own whose sent frames are kept, not sent."""

    def __init__(self):
        super().__init__(can.Bus(interface="virtual", channel=f"n-{uuid.uuid4().hex}"))
        self.sent: list[Frame] = []

    def send_frames(self, frames) -> None:
        self.sent += frames


def test_canopen_hears_the_routers_frames_and_sends_frames_through_it():
    router = SentFrames()
    try:
        network = RoutedNetwork(router)
        heard = []

        def callback(can_id: int, data: bytearray, timestamp: float) -> None:
            heard.append((can_id, data, timestamp))

        network.subscribe(0x181, callback)
        network.subscribe(0x181, callback)                  # canopen subscribes it once
        router.on_frames([Frame(0x181, b"\x01\x02", timestamp=5.0),
                          Frame(0x181, b"\x03", extended=True)])   # another frame
        assert heard == [(0x181, bytearray(b"\x01\x02"), 5.0)]
        assert isinstance(heard[0][1], bytearray)
        network.unsubscribe(0x181, callback)
        assert router.handlers(0x181) == ()
        network.send_message(0x601, bytearray(b"\x40\x00\x10\x00"))
        network.send_message(0x12345, [1, 2])
        network.send_message(0x181, b"", remote=True)
        assert router.sent == [Frame(0x601, b"\x40\x00\x10\x00"),
                               Frame(0x12345, b"\x01\x02", extended=True),
                               Frame(0x181, remote=True)]
    finally:
        router.bus.shutdown()


def test_a_drive_that_leaves_its_bus_leaves_no_handler_on_its_router():
    router = SentFrames()
    try:
        drive = Cia402Drive(drive_config(1), DriveCore(DriveParameters(**TEST_MOTOR_DRIVE)),
                            threading.Lock())
        drive.attach(router)
        router.on_frames([Frame(0x000, bytes([0x01, 0]))])      # NMT start: PDOs again
        assert router.sent[0] == Frame(0x701, b"\x00")          # its boot-up
        drive.detach()
        assert not router.has_subscribers()
    finally:
        router.bus.shutdown()
