"""Frames between hil's own ends on the ``zenoh`` interface go as
:class:`~hil.can.frame.Frame` values, remote and extended ones too: no ``can.Message`` is
built for them where every listener takes frames."""

from __future__ import annotations

import threading
import time
from collections.abc import Sequence

import can

from hil.can.delivery import FrameListener
from hil.can.frame import Frame
from hil.can.router import start_router


class ValuesRecorder(FrameListener):
    """Records each frame with the way it came: ``("frame", frame)`` or
    ``("message", msg)``."""

    def __init__(self):
        self.got: list[tuple] = []
        self._arrived = threading.Condition()

    def on_frames(self, frames: Sequence[Frame]) -> None:
        for frame in frames:
            # the clock a frame carries is the transport's; the values are what is pinned
            self._add(("frame", frame._replace(timestamp=0.0)))

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


def test_hils_routers_send_and_receive_a_cycle_as_values(bus_pair):
    a, b = bus_pair
    master = start_router(a)
    recorder = ValuesRecorder()
    b.deliver_to([recorder])
    cycle = [Frame(0x201, b"\x01\x02"), Frame(0x80)]
    master.send_frames(cycle)
    assert recorder.wait_for(2) == [("frame", frame) for frame in cycle]
    master.stop()


def test_a_remote_frame_and_an_extended_low_id_come_as_values_with_their_flags(bus_pair):
    a, b = bus_pair
    recorder = ValuesRecorder()
    b.deliver_to([recorder])
    a.send(can.Message(arbitration_id=0x5, data=b"\x07", is_extended_id=True))
    a.send(can.Message(arbitration_id=0x601, is_remote_frame=True, dlc=8, is_extended_id=False))
    assert recorder.wait_for(2) == [("frame", Frame(0x5, b"\x07", extended=True)),
                                    ("frame", Frame(0x601, bytes(8), remote=True))]


def test_a_remote_frame_reaches_a_listener_that_wants_messages_as_one(bus_pair):
    a, b = bus_pair
    recorder = ValuesRecorder()
    b.deliver_to([recorder, lambda msg: None])     # a plain callable wants messages
    a.send(can.Message(arbitration_id=0x601, is_remote_frame=True, dlc=8, is_extended_id=False))
    (kind, msg), = recorder.wait_for(1)
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


def test_buses_of_one_session_hand_a_frame_listener_values(endpoint):
    channel = f"test/{time.monotonic_ns()}"
    a, b = (can.Bus(interface="zenoh", channel=channel, listen=[endpoint]) for _ in range(2))
    try:
        recorder = ValuesRecorder()
        b.deliver_to([recorder])
        a.send(can.Message(arbitration_id=0x1ABCDEF0, data=b"\x03", is_extended_id=True))
        assert recorder.wait_for(1) == [("frame", Frame(0x1ABCDEF0, b"\x03", extended=True))]
    finally:
        a.shutdown()
        b.shutdown()
