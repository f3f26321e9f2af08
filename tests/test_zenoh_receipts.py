"""What a lossless bus asks the monitors at its shutdown: which frame of it each has heard
(hil.can.zenoh_receipts), over a real Zenoh session on loopback."""

from __future__ import annotations

import threading
import time

import can
import pytest

from hil.can.zenoh_receipts import (declare_receipts, monitors_behind, receipts_payload,
                                   wait_for_monitor)
from hil.zenoh_session import ZenohSettings, close, free_loopback_port, session


def test_receipts_are_a_line_per_channel_and_sender():
    assert receipts_payload([("ur3/arm", {7: 41, 9: 2}), ("ur3/wrist", {})]) == \
        b"ur3/arm 7 41\nur3/arm 9 2\n"


@pytest.fixture
def two_sessions():
    endpoint = f"tcp/127.0.0.1:{free_loopback_port()}"
    monitor, sender = ZenohSettings(listen=(endpoint,)), ZenohSettings(connect=(endpoint,))
    yield session(monitor), session(sender)
    close(sender)
    close(monitor)


def test_a_monitor_is_behind_a_sender_until_it_has_heard_its_last_frame(two_sessions):
    monitor, sender = two_sessions
    heard = {"ur3/arm": {7: 0xFFFFFFFE}}
    queryable = declare_receipts(monitor, lambda: list(heard.items()))
    try:
        # the queryable's declaration reaches the other session on its own time
        deadline = time.monotonic() + 10
        while monitors_behind(sender, "ur3/arm", 7, 3) != 1:     # numbers wrap at 32 bits
            assert time.monotonic() < deadline, "the monitor never answered"
            time.sleep(0.01)
        assert monitors_behind(sender, "ur3/arm", 7, 0xFFFFFFFE) == 0
        heard["ur3/arm"][7] = 3
        assert monitors_behind(sender, "ur3/arm", 7, 3) == 0
        # a monitor that never heard this sender, or this channel, waits for nothing
        assert monitors_behind(sender, "ur3/arm", 8, 3) == 0
        assert monitors_behind(sender, "ur3/wrist", 7, 3) == 0
    finally:
        queryable.undeclare()


def test_a_sender_awaiting_a_monitor_waits_for_one_then_the_monitor_hears_its_first_frame():
    """``--await-monitor`` (hil up --lock-step): the sender's session learns of the monitor
    before its first frame, so the log holds it (a lock-step log lacked every drive's boot-up,
    put while the visualiser's subscription was on its way)."""
    endpoint = f"tcp/127.0.0.1:{free_loopback_port()}"
    sender_settings = ZenohSettings(listen=(endpoint,))
    monitor_settings = ZenohSettings(connect=(endpoint,))
    sender = can.Bus(interface="zenoh", channel="ur3/arm", settings=sender_settings)
    monitor = None
    try:
        assert not wait_for_monitor(session(sender_settings), timeout=0.3)   # none there yet
        found: list[bool] = []
        waiting = threading.Thread(target=lambda: found.append(
            wait_for_monitor(session(sender_settings), timeout=20)))
        waiting.start()
        time.sleep(0.3)
        assert waiting.is_alive() and not found
        monitor = can.Bus(interface="zenoh", channel="ur3/arm", settings=monitor_settings,
                          timestamps="sent")
        waiting.join(30)
        assert found == [True]
        sender.send(can.Message(arbitration_id=0x701, data=b"\x00", is_extended_id=False))
        first = monitor.recv(5)
        assert first is not None and first.arbitration_id == 0x701 and first.data == b"\x00"
    finally:
        for bus in (sender, monitor):
            if bus is not None:
                bus.shutdown()
        close(monitor_settings)
        close(sender_settings)
