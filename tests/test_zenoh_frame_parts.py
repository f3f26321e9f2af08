"""Frames between hil's own ends on the ``zenoh`` interface go as their parts (dispatch key and
data): no ``can.Message`` is built for them, and what is not a plain data frame still
arrives as a message."""

from __future__ import annotations

import threading
import time

import can

from hil.can.delivery import FrameListener
from hil.can.messages import EXTENDED
from hil.can.network import start_network


class PartsRecorder(FrameListener):
    """Records each frame with the way it came: ``("parts", key, data)`` or
    ``("message", msg)``."""

    def __init__(self):
        self.got: list[tuple] = []
        self._arrived = threading.Condition()

    def on_frame(self, key: int, data: bytearray, timestamp: float) -> None:
        self._add(("parts", key, bytes(data)))

    def on_message_received(self, msg: can.Message) -> None:
        self._add(("message", msg))

    def _add(self, entry: tuple) -> None:
        with self._arrived:
            self.got.append(entry)
            self._arrived.notify_all()

    def wait_for(self, count: int, timeout: float = 5.0) -> list[tuple]:
        with self._arrived:
            assert self._arrived.wait_for(lambda: len(self.got) >= count, timeout), self.got
            return list(self.got)


def test_hils_networks_send_and_receive_a_cycle_as_parts(bus_pair):
    a, b = bus_pair
    master = start_network(a)
    assert master.frame_sender is not None
    recorder = PartsRecorder()
    b.deliver_to([recorder])
    master.send_frames([(0x201, b"\x01\x02"), (0x80, b"")])
    assert recorder.wait_for(2) == [("parts", 0x201, b"\x01\x02"), ("parts", 0x80, b"")]
    master.disconnect()


def test_a_remote_frame_comes_as_a_message_and_an_extended_low_id_keeps_its_flag(
        bus_pair):
    a, b = bus_pair
    recorder = PartsRecorder()
    b.deliver_to([recorder])
    a.send(can.Message(arbitration_id=0x5, data=b"\x07", is_extended_id=True))
    a.send(can.Message(arbitration_id=0x601, is_remote_frame=True, dlc=8, is_extended_id=False))
    first, second = recorder.wait_for(2)
    assert first == ("parts", 0x5 | EXTENDED, b"\x07")
    kind, msg = second
    assert kind == "message" and msg.is_remote_frame and msg.is_rx
    assert (msg.arbitration_id, msg.dlc, msg.is_extended_id, bytes(msg.data)) == (
        0x601, 8, False, b"")


def test_a_frame_changed_after_its_send_goes_out_as_it_was_sent(bus_pair):
    """python-can leaves a message to its caller once ``send`` returns; in a batch the frame
    is put later, so the bus keeps its own copy."""
    a, b = bus_pair
    msg = can.Message(arbitration_id=0x181, data=b"\x01\x02", is_extended_id=False)
    with a.batch():
        a.send(msg)
        msg.data[0] = 0xFF
    received = b.recv(5)
    assert received is not None and bytes(received.data) == b"\x01\x02"


def test_buses_of_one_session_hand_a_frame_listener_parts(endpoint):
    channel = f"test/{time.monotonic_ns()}"
    a, b = (can.Bus(interface="zenoh", channel=channel, listen=[endpoint]) for _ in range(2))
    try:
        recorder = PartsRecorder()
        b.deliver_to([recorder])
        a.send(can.Message(arbitration_id=0x1ABCDEF0, data=b"\x03", is_extended_id=True))
        assert recorder.wait_for(1) == [("parts", 0x1ABCDEF0, b"\x03")]
    finally:
        a.shutdown()
        b.shutdown()
