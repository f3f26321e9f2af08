"""What must never move a Robstride or CyberGear motor (docs/protocols/robstride.md): every
special frame, private protocol and MIT mode, sent ten times to an enabled motor; and a frame
of the other framing (11-bit to a motor in private mode, 29-bit to one in MIT mode), ignored
and logged naming bus and id (lerobot #3547). The motors are tests/test_robstride.py's."""

from __future__ import annotations

import logging
import struct

import pytest

from hil.drives import Power
from hil.protocols.mit import MitCommand, MitRanges, pack_command
from hil.protocols.robstride import params as P
from hil.protocols.robstride.codec import Comm, private_id
from test_robstride import (  # noqa: F401 (rs03, mit_rs00: fixtures)
    HOLD, HOST, mit_rs00, move_in_operation_control, rs03, rs03_ranges,
)

# --- ten special frames to an enabled motor move nothing ---------------------------------

SPECIAL_PRIVATE = {
    "enable": (Comm.ENABLE, bytes(8)), "stop": (Comm.STOP, bytes(8)),
    "clear-faults": (Comm.STOP, bytes([1]) + bytes(7)), "device-id": (Comm.GET_DEVICE_ID, bytes(8)),
    "set-zero": (Comm.SET_ZERO, bytes([1]) + bytes(7)),
    "read": (Comm.READ_PARAMETER, P.parameter_frame(P.MECH_POS)),
    "fault": (Comm.FAULT_FEEDBACK, bytes(8)), "save": (Comm.SAVE_PARAMETERS, bytes(range(1, 9))),
    "report-off": (Comm.ACTIVE_REPORTING, bytes([1, 2, 3, 4, 5, 6, 0, 8])),
    "baud": (Comm.BAUD_RATE, bytes([1, 2, 3, 4, 5, 6, 1, 8])),
    "protocol": (Comm.PROTOCOL, bytes([1, 2, 3, 4, 5, 6, 0, 8]))}


@pytest.mark.parametrize("name", SPECIAL_PRIVATE)
def test_no_special_frame_sent_ten_times_moves_an_enabled_motor(rs03, name):
    comm, data = SPECIAL_PRIVATE[name]
    move_in_operation_control(rs03, 0.3, rs03_ranges())
    before = rs03.joint()
    for _ in range(10):
        rs03.request(comm, data)
    rs03.wait(200)
    assert rs03.joint() == pytest.approx(before, abs=HOLD)


SPECIAL_MIT = {"enable": "FFFC", "stop": "FFFD", "set-zero": "FFFE", "clear-fault": "FFFB",
               "read-fault": "00FB", "run-mode-mit": "00FC", "protocol-private": "00FD"}


def rs00_mit_ranges() -> MitRanges:
    return MitRanges(12.57, 33.0, 500.0, 5.0, 14.0)


@pytest.mark.parametrize("name", SPECIAL_MIT)
def test_no_mit_special_frame_sent_ten_times_moves_an_enabled_motor(mit_rs00, name):
    """RS00 MIT commands 1, 2, 4, 5, 6 and 8, each ten times."""
    master = mit_rs00
    master.ask(0x001, bytes([0xFF] * 7 + [0xFC]), extended=False)
    hold = pack_command(MitCommand(0.3, 0.0, 10.0, 0.5, 0.0), rs00_mit_ranges())
    for _ in range(300):
        master.ask(0x001, hold, extended=False)
    before = master.joint()
    for _ in range(10):
        assert len(master.ask(0x001, bytes([0xFF] * 6) + bytes.fromhex(SPECIAL_MIT[name]),
                              extended=False)) == 1            # each answered
    master.wait(200)
    assert master.joint() == pytest.approx(before, abs=HOLD)


def test_mit_position_and_speed_control_follow_their_run_mode(mit_rs00):
    """RS00 MIT commands 6, 1, 10 (ids 0x100 | id, float position and speed)."""
    master = mit_rs00
    master.ask(0x001, bytes([0xFF] * 6 + [1, 0xFC]), extended=False)
    master.ask(0x001, bytes([0xFF] * 7 + [0xFC]), extended=False)
    master.ask(0x101, struct.pack("<ff", 0.4, 3.0), extended=False)
    master.wait(500)
    assert master.joint() == pytest.approx(0.4, abs=0.02)
    (answer,) = master.ask(0x201, struct.pack("<ff", 5.0, 2.0), extended=False)
    master.wait(100)
    assert master.joint() == pytest.approx(0.4, abs=0.02)     # not in speed mode
    (answer,) = master.ask(0x001, bytes([0xFF] * 6 + [5, 0xFA]), extended=False)
    assert (answer.arbitration_id, bytes(answer.data[:3])) == (5, b"hil")   # answer 2


# --- the wrong framing -------------------------------------------------------------------

def test_an_11_bit_frame_to_a_motor_in_private_mode_is_ignored_and_logged(rs03, caplog):
    """LeRobot #3547: a Damiao-style 11-bit frame gets no answer from a factory motor; the
    simulator's log names the bus and the id."""
    move_in_operation_control(rs03, 0.3, rs03_ranges())
    before = rs03.joint()
    with caplog.at_level(logging.WARNING):
        for _ in range(10):
            assert rs03.ask(0x001, bytes([0xFF] * 7 + [0xFB]), extended=False) == []
    rs03.wait(100)
    assert rs03.joint() == pytest.approx(before, abs=HOLD)
    assert "bus 'legs': 11-bit frame 0x1 reached Robstride motor 1" in caplog.text
    assert caplog.text.count("11-bit frame") == 1                 # once per identifier


def test_a_29_bit_frame_to_a_motor_in_mit_mode_is_ignored_and_logged(mit_rs00, caplog):
    with caplog.at_level(logging.WARNING):
        assert mit_rs00.request(Comm.ENABLE) == []
    assert mit_rs00.drive.core.power is not Power.ENABLED
    assert f"29-bit frame 0x{private_id(Comm.ENABLE, HOST, 1):X}" in caplog.text
