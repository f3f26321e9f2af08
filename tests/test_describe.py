"""hil describe: what the user's own master needs, from the config and the protocols alone
(issue 46: it took the YAML, the EDS' comment header and a guessed gear ratio)."""

from __future__ import annotations

from conftest import TESTS
from hil.cli import main


def test_a_cia402_config_is_described_for_a_canopen_master(capsys):
    assert main(["describe", "ur3"]) == 0
    said = capsys.readouterr().out
    assert 'join it: can.Bus(interface="zenoh", channel="ur3/arm")' in said
    assert "node 2: joint2 (cia402); the motor turns 120 rad per joint rad; 131072 counts" in said
    assert "0x202  6 B      500/s  master: RPDO1" in said
    assert "0x182  6 B      500/s  drive: TPDO1" in said
    assert "SYNC 0x080 every cycle (500/s)" in said
    assert "RPDO1: 0x6040 Controlword, 0x607A Target position" in said
    assert "TPDO1: 0x6041 Statusword, 0x6064 Position actual value" in said


def test_a_servo_mode_motor_is_described_with_its_extended_ids(tmp_path, capsys):
    config = tmp_path / "servo.yaml"
    config.write_text((TESTS / "fixtures" / "cubemars_one_axis.yaml").read_text()
                      .replace("kp: 5.0", "control: servo, kp: 5.0")
                      .replace("robot: damiao_one_axis.urdf",
                               f"robot: {TESTS / 'fixtures' / 'damiao_one_axis.urdf'}"))
    assert main(["describe", str(config)]) == 0
    said = capsys.readouterr().out
    assert "0x601 ext  8 B      500/s  master: position_speed command" in said
    assert "0x2901 ext  8 B       50/s  drive: status" in said
    assert "EDS" not in said


def test_an_unknown_robot_is_an_error_naming_the_known_ones(capsys):
    assert main(["describe", "nosuch"]) == 1
    said = capsys.readouterr().err
    assert "no bus config for robot 'nosuch'" in said and "ur3" in said


def test_a_prismatic_joints_reduction_is_given_per_metre(capsys):
    """Issue 64: the pigot's gripper slide was described "rad per joint rad"; a reduction is
    per unit of its first joint (RobotDescription.reduction): a prismatic joint's metre."""
    assert main(["describe", "pigot"]) == 0
    said = capsys.readouterr().out
    assert "node 7: finger_pri_1 (cia402); the motor turns 3141.59 rad per joint m;" in said
    assert "node 2: arm_rot_2 (cia402); the motor turns" in said and "per joint rad;" in said
