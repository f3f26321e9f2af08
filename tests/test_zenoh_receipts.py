"""What a lossless bus asks the monitors at its shutdown: which frame of it each has heard
(hil.can.zenoh_receipts), over a real Zenoh session on loopback."""

from __future__ import annotations

import time

import pytest

from hil.can.zenoh_receipts import declare_receipts, monitors_behind, receipts_payload
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
