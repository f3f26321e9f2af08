"""Published Robstride and CyberGear clients, unchanged, drive hil's motors through their own
documented sequences (docs/protocols/robstride.md, "Clients"): kscale's ``robstride``
(private protocol), ``python-cybergear`` (a CyberGear in position mode) and LeRobot 0.4.4's
``RobstrideMotorsBus`` (through the MIT protocol mode it speaks; a motor in the private
protocol does not answer it, as on hardware: lerobot #3547). The motors and their config are
tests/test_robstride.py's."""

from __future__ import annotations

import logging
import math
import time

import pytest

from hil.drives import Power
from hil.protocols.robstride.codec import MotorMode
from hil.testing import DrivesBench
from test_robstride import config

@pytest.mark.real_time
def test_kscale_robstride_client_drives_position_mode_through_its_commands(tmp_path):
    """``robstride`` 0.1.0 (its CLI's enable, write, read, update_id, disable), host 0xAA,
    its ``motor_model=1`` ranges (RS01: ±44 rad/s, ±17 N·m)."""
    robstride = pytest.importorskip("robstride")
    path = config(tmp_path, "model: RS01", "peak_torque: 17, rated_torque: 6, max_velocity: 44,")
    with DrivesBench(path) as bench:
        client = robstride.Client(bench.bus("legs"), recv_timeout=2)
        client.write_param(1, "run_mode", robstride.RunMode.Position)
        assert client.read_param(1, "run_mode") is robstride.RunMode.Position
        client.enable(1)
        client.write_param(1, "loc_ref", 0.5)
        deadline = time.monotonic() + 20
        while abs(client.read_param(1, "mechpos") - 0.5) > 0.01:
            assert time.monotonic() < deadline
            time.sleep(0.05)
        assert bench.joint("yaw") == pytest.approx(0.5, abs=0.02)
        stopped = client.disable(1)
        assert stopped.angle == pytest.approx(0.5, abs=0.02) and stopped.errors == []
        client.update_id(1, 7)
        assert client.enable(7).servo_id == 7


@pytest.mark.real_time
def test_python_cybergear_drives_a_cybergear_in_position_mode_through_its_readme(tmp_path):
    """``python-cybergear`` 0.1.2 (its class docstring's sequence: run_mode, enable, the
    reference; its loc_ref sends limit_spd first), polling its parameters; its device-id
    request is one byte long."""
    cybergear = pytest.importorskip("cybergear")
    with DrivesBench(config(tmp_path, "model: CyberGear")) as bench:
        with cybergear.CyberGearMotor(bus_config={"interface": bench.interface,
                                                  "channel": bench.channel("legs")},
                                      can_id=1, poll_interval=0.05) as motor:
            assert motor.device_id is not None
            motor.run_mode = "position"
            motor.enable()
            motor.limit_spd = 5.0
            motor.loc_ref = 0.5
            deadline = time.monotonic() + 20
            while motor.mech_pos is None or abs(motor.mech_pos - 0.5) > 0.01:
                assert time.monotonic() < deadline
                time.sleep(0.05)
            assert bench.joint("yaw") == pytest.approx(0.5, abs=0.02)
            assert motor.feedback.mode == MotorMode.RUN and not motor.feedback.faults.has_fault
            motor.disable()


LEROBOT_MOTORS = {"knee": 1}


def lerobot_bus(bench: DrivesBench):
    from lerobot.motors import Motor, MotorNormMode
    from lerobot.motors.robstride import RobstrideMotorsBus

    return RobstrideMotorsBus(
        port=bench.channel("legs"), can_interface="hil-virtual", use_can_fd=False,
        motors={name: Motor(node, "O0", MotorNormMode.DEGREES, motor_type_str="O0")
                for name, node in LEROBOT_MOTORS.items()})


@pytest.mark.real_time
def test_lerobot_robstride_bus_drives_a_motor_in_mit_protocol_mode(tmp_path):
    """LeRobot 0.4.4's bus ("the motors need to be switched to MIT control mode"): connect
    (its handshake: FF x 6 FF FB per motor), configure_motors (enable, MIT run mode),
    Goal_Position in degrees with its kp 10, kd 0.5, Present_Position, disconnect (stop),
    on an RS00 (its O0's ranges ±33 rad/s, ±14 N·m)."""
    pytest.importorskip("lerobot")
    with DrivesBench(config(tmp_path, "model: RS00, protocol: mit")) as bench:
        bus = lerobot_bus(bench)
        bus.connect()
        try:
            bus.configure_motors()
            deadline = time.monotonic() + 20
            while abs(bus.sync_read("Present_Position")["knee"] - 20.0) > 1.0:
                assert time.monotonic() < deadline
                bus.sync_write("Goal_Position", {"knee": 20.0})
                time.sleep(0.01)
            assert math.degrees(bench.joint("yaw")) == pytest.approx(20.0, abs=1.5)
        finally:
            bus.disconnect()
        assert bench.sim.drives[0].core.power is Power.DISABLED


@pytest.mark.real_time
def test_lerobot_robstride_bus_meets_a_factory_motor_as_the_hardware_does(tmp_path, caplog):
    """lerobot #3547: its 11-bit frames reach a motor in the private protocol it ships in;
    the motor does not answer, the handshake fails, and hil's log names bus and id."""
    pytest.importorskip("lerobot")
    with DrivesBench(config(tmp_path, "model: RS00")) as bench:
        bus = lerobot_bus(bench)
        with caplog.at_level(logging.WARNING), pytest.raises(ConnectionError,
                                                             match="did not respond"):
            bus.connect()
    assert "bus 'legs': 11-bit frame 0x1 reached Robstride motor 1" in caplog.text
