"""Published MyActuator RMD clients, unchanged, drive hil's motors through their own
documented sequences (docs/protocols/myactuator.md, "Clients"): NekoRMD over python-can,
motorbridge and 2b-t/myactuator_rmd's Python bindings over SocketCAN (inside User-Mode
Linux). The motors and their config are tests/test_myactuator.py's."""

from __future__ import annotations

import math
import time

import pytest

from conftest import RealTimeMaster, socketcan_missing
from hil.drives import Power
from hil.protocols.myactuator.codec import Command
from test_myactuator import DEG, one_axis

@pytest.fixture
def master(tmp_path):
    """A real-time bench of the one-axis X8-20 and a master's bus beside it."""
    bench = RealTimeMaster.of(one_axis(tmp_path))
    try:
        yield bench
    finally:
        bench.close()


@pytest.mark.real_time
def test_nekormd_drives_the_motor_through_its_readme_sequence(master):
    """NekoRMD 0.2.2's README: NekoRMD(address, MotorType.RMD8x_pro), unfreeze (0x77),
    set_absolute_position (0xA4, angle in 0.01°), set_speed (0xA2), freeze (0x81). Its
    ``setup()`` brings up SocketCAN can0 with sudo: the bus is given instead (python-can's
    ``virtual``); ``init()`` sends 0x88, V2's "motor running", which V4.2 lacks: the motor
    does not answer, and NekoRMD's ``recv()`` without a timeout would wait forever, so the
    sequence starts at unfreeze. NekoRMD checks each answer's id against the command's id:
    V4.2 answers on 0x240 + id (§1.1.2), so its methods return None on hil's motor as on a
    V4.2 motor."""
    import can
    from NekoRMD.MotorType import MotorType
    from NekoRMD.NekoRMD import NekoRMD

    motor = NekoRMD(address=0x141, motor_type=MotorType.RMD8x_pro)
    motor.io.bus = can.Bus(interface=master.interface, channel=master.channel)
    try:
        motor.control.unfreeze()
        motor.control.position.set_absolute_position(max_speed=200, angle=9000)
        deadline = time.monotonic() + 5.0
        while time.monotonic() < deadline and abs(master.joint() - math.pi / 2) > 0.01:
            time.sleep(0.05)
        assert master.joint() == pytest.approx(math.pi / 2, abs=0.01)
        motor.control.speed.set_speed(30)
        time.sleep(0.5)
        assert master.drive.core.status().velocity == pytest.approx(30 * DEG, abs=0.05)
        motor.control.freeze()
        time.sleep(0.3)
        here = master.joint()
        time.sleep(0.3)
        assert master.joint() == pytest.approx(here, abs=0.01)
    finally:
        motor.io.bus.shutdown()


@pytest.mark.socketcan
def test_motorbridge_drives_the_motor_through_its_documented_sequence_over_socketcan(
        tmp_path):
    """``motorbridge`` 0.5.6 (SocketCAN only on Linux: run inside User-Mode Linux's vcan0),
    its MyActuator reference (motor_cli/MYACTUATOR_API.md): add_myactuator_motor(1, 0x241),
    enable (0x77), send_pos_vel (0xA4), poll the feedback (status 2, 0x9C), get_state,
    disable (0x80). motorbridge reads status 2's angle as 0.01° a bit; §2.15.3 gives 1° a bit
    (int16, "maximum range ±32767degree"), as 2b-t/myactuator_rmd's FeedbackResponse reads
    it: hil follows the document, so motorbridge's ``pos`` is the shaft's 1/100 (57° at
    1 rad read as 0.57°)."""
    missing = socketcan_missing()
    if missing:
        pytest.skip(missing)
    from motorbridge import Controller

    master = RealTimeMaster.of(one_axis(tmp_path), vcan="vcan0")
    try:
        with Controller("vcan0") as controller:
            motor = controller.add_myactuator_motor(1, 0x241, "X8")
            motor.enable()
            deadline = time.monotonic() + 4.0
            while time.monotonic() < deadline:
                motor.send_pos_vel(1.0, 3.0)
                motor.request_feedback()
                controller.poll_feedback_once()
                time.sleep(0.02)
            # the last poll may have read the 0xA4's answer alone, the 0x9C's still on its
            # way (a host stalled inside User-Mode Linux): polled again, as its user would
            state = motor.get_state()
            deadline = time.monotonic() + 4.0
            while ((state is None or state.status_code != Command.READ_STATUS_2)
                   and time.monotonic() < deadline):
                motor.request_feedback()
                time.sleep(0.02)
                controller.poll_feedback_once()
                state = motor.get_state()
            assert master.joint() == pytest.approx(1.0, abs=0.02)
            assert state is not None and state.status_code == Command.READ_STATUS_2
            assert state.pos == pytest.approx(round(math.degrees(1.0)) * 0.01 * DEG, abs=1e-4)
            motor.disable()
            time.sleep(0.1)
            assert master.drive.core.power is Power.DISABLED
    finally:
        master.close()
