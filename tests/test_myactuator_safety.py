"""What must never move a MyActuator RMD motor, and how it stops on its own (docs/protocols/
myactuator.md): every read and setting command sent ten times to a holding motor; a frame of
the wrong framing or another family's ids, ignored and logged naming bus and id; the CAN
timeout (§2.30) and an injected fault (§2.14). The motors are tests/test_myactuator.py's."""

from __future__ import annotations

import logging
import struct
import threading

import pytest

from hil.drives import Power
from hil.protocols.myactuator import MyActuatorOptions
from hil.protocols.myactuator.codec import ErrorState, unpack_status_1
from hil.protocols.myactuator.drive import MyActuatorDrive
from test_mit_profile import LockStep, core, drive_config
from test_myactuator import DEG, rmd  # noqa: F401 (rmd: a fixture)

# --- what never moves the motor -------------------------------------------------------------

#: every read and setting command with data a master sends (the document's examples)
NOT_MOVING = {
    "0x30": bytes.fromhex("3001000000000000"), "0x31": bytes.fromhex("3101000000000040"),
    "0x32": bytes.fromhex("3201000000000040"), "0x42": bytes.fromhex("4200000000000000"),
    "0x43": bytes.fromhex("4300000010270000"), "0x60": bytes.fromhex("6000000000000000"),
    "0x61": bytes.fromhex("6100000000000000"), "0x62": bytes.fromhex("6200000000000000"),
    "0x63": bytes.fromhex("6300000010270000"), "0x64": bytes.fromhex("6400000000000000"),
    "0x90": bytes.fromhex("9000000000000000"), "0x92": bytes.fromhex("9200000000000000"),
    "0x94": bytes.fromhex("9400000000000000"), "0x9A": bytes.fromhex("9A00000000000000"),
    "0x9C": bytes.fromhex("9C00000000000000"), "0x9D": bytes.fromhex("9D00000000000000"),
    "0x70": bytes.fromhex("7000000000000000"), "0x71": bytes.fromhex("7100000000000000"),
    "0x77": bytes.fromhex("7700000000000000"), "0x79": bytes.fromhex("7900010000000000"),
    "0xB1": bytes.fromhex("B100000000000000"), "0xB2": bytes.fromhex("B200000000000000"),
    "0xB3": bytes.fromhex("B300000000000000"), "0xB4": bytes.fromhex("B400000000000001"),
    "0xB5": bytes.fromhex("B500000000000000"), "0xB6": bytes.fromhex("B660010100000000"),
    "0x20": bytes.fromhex("2002000000000000"), "0x81": bytes.fromhex("8100000000000000"),
}


@pytest.mark.parametrize("name", NOT_MOVING)
def test_read_and_setting_commands_ten_times_move_nothing(rmd, name):
    """Issue 68: every read and setting command, ten times to a motor holding at 0.5 rad
    (0xA4), moves nothing; the stop (0x81) holds where it is (§2.18.1)."""
    rmd.move(0.5 / DEG)
    rmd.wait(0.8)
    before = rmd.joint()
    for _ in range(10):
        rmd.send(0x141, NOT_MOVING[name])
    rmd.wait(0.5)
    assert rmd.joint() == pytest.approx(before, abs=0.005)
    assert rmd.drive.core.power is Power.ENABLED


# --- the wrong framing ------------------------------------------------------------------

@pytest.mark.parametrize("can_id, data, extended, words", [
    (0x141, bytes([0x9A]) + bytes(7), True, "a 29-bit frame on its id"),
    (0x141, bytes.fromhex("FFFFFFFFFFFFFFFC"), False, "unknown command byte 0xFF"),
    (0x141, bytes([0xA2, 0, 0, 0, 0x10, 0x27]), False, "6 data bytes, not 8"),
], ids=["29-bit", "mit-enter-motor-mode", "short"])
def test_a_frame_of_the_wrong_framing_moves_nothing_is_unanswered_and_logged(
        rmd, caplog, can_id, data, extended, words):
    """§1.1.2: standard frames, DLC 8; a 29-bit frame, an MIT motor's FF x 7 FC, a short
    frame: ignored unanswered (hil's reading), logged naming bus and id."""
    before = rmd.joint()
    with caplog.at_level(logging.WARNING):
        for _ in range(10):
            assert rmd.send(can_id, data, extended=extended) == []
    rmd.wait(0.3)
    assert rmd.joint() == pytest.approx(before, abs=1e-4)
    assert rmd.drive.core.power is Power.DISABLED
    logged = [r.getMessage() for r in caplog.records if words in r.getMessage()]
    assert len(logged) == 1 and "bus 'leg' node 1" in logged[0] and "0x141" in logged[0]


def test_another_familys_frames_reach_nothing(rmd):
    """A Damiao command on 0x001 and a Robstride 29-bit frame: no id of the motor."""
    assert rmd.send(0x001, bytes.fromhex("FFFFFFFFFFFFFFFC")) == []
    assert rmd.send(0x0300FD01, bytes(8), extended=True) == []
    assert rmd.drive.core.power is Power.DISABLED


# --- the CAN timeout (§2.30), off any bus, lock-step clock --------------------------------

def test_can_timeout_cuts_the_output_and_the_next_command_runs_again_2_30():
    """§2.30.4: 1000 ms written; past it without a frame "the output lock brake will be cut
    off"; "when the communication interval is restored ... normal operation can be
    resumed". 0 (as shipped) never cuts."""
    drive = MyActuatorDrive(drive_config(1, "myactuator", MyActuatorOptions()),
                            core(peak=20.0), threading.RLock())
    bench = LockStep(drive)
    speed = bytes([0xA2, 0, 0, 0]) + struct.pack("<i", 1000)
    bench.send(0x141, speed)
    bench.wait(2.0)
    assert drive.core.power is Power.ENABLED                       # off as shipped
    bench.send(0x141, bytes.fromhex("B3000000E8030000"))
    assert drive.take_replies()[0].data == bytes.fromhex("B3000000E8030000")
    bench.send(0x141, speed)
    bench.wait(0.9)
    assert drive.core.power is Power.ENABLED
    bench.wait(0.2)
    assert drive.core.power is Power.DISABLED and not drive.brake_released
    bench.send(0x141, speed)
    assert drive.core.power is Power.ENABLED


def test_an_injected_fault_is_over_current_until_the_system_reset_2_14_8_2():
    drive = MyActuatorDrive(drive_config(1, "myactuator", MyActuatorOptions()),
                            core(peak=20.0), threading.RLock())
    bench = LockStep(drive)
    bench.send(0x141, bytes([0xA2, 0, 0, 0]) + struct.pack("<i", 1000))
    from hil.drives.definitions import Fault

    drive.core.raise_fault(Fault.EMERGENCY_STOP)
    bench.wait(0.01)
    bench.send(0x141, bytes([0x9A]) + bytes(7))
    assert unpack_status_1(drive.take_replies()[0].data)[3] == ErrorState.OVER_CURRENT
    bench.send(0x141, bytes([0xA2, 0, 0, 0]) + struct.pack("<i", 1000))
    assert drive.core.power is not Power.ENABLED                   # "not faulty" only
    bench.send(0x141, bytes([0x76]) + bytes(7))
    bench.send(0x141, bytes([0x9A]) + bytes(7))
    assert unpack_status_1(drive.take_replies()[0].data)[3] == ErrorState(0)
