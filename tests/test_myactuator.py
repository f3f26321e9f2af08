"""MyActuator RMD-X motors as the maker's *Motor Motion Control Command Protocol* V4.2
(2024-05) describes them: a test per command citing its section, every read and setting
command ten times to a running motor (nothing moves), frames of the wrong framing, hil's
own master, a lock-step log replayed bit for bit, and published client libraries (NekoRMD
0.2.2 over python-can; motorbridge 0.5.6 over SocketCAN, inside User-Mode Linux).

The document's byte examples (its "Communication Example" subsections) are the codec's
vectors; the motors run lock-step on a one-axis plant (the Damiao tests' disc, an X8-20 at
its output)."""

from __future__ import annotations

import math
import struct
from pathlib import Path

import pytest

from conftest import TESTS, hils_master_moves
from hil.bus_config import load_bus_config
from hil.drives import Power
from hil.protocols.mit import unpack_command
from hil.protocols.myactuator import MyActuator, MyActuatorOptions
from hil.protocols.myactuator.codec import (
    MIT_RANGES, ErrorState, MotorState, pack_state, pack_status_1, unpack_mit_reply,
    unpack_state, unpack_status_1,
)
from hil.protocols.myactuator.drive import MyActuatorDrive
from hil.protocols.myactuator.models import MODELS, model
from hil.testing import DrivesBench
from test_mit_profile import PlantMaster

URDF = TESTS / "fixtures" / "damiao_one_axis.urdf"
#: the output degrees in radians
DEG = math.pi / 180


def one_axis(folder: Path, holding_brake: bool = False) -> Path:
    """A bus config of one X8-20 (node 1) on the disc's axis, hil's master gains given; the
    joint's range widened to ±20 rad for the multi-turn commands."""
    robot = folder / "rmd_one_axis.urdf"
    robot.write_text(URDF.read_text().replace('lower="-3.0" upper="3.0"',
                                              'lower="-20.0" upper="20.0"'))
    path = folder / "rmd_one_axis.yaml"
    brake = ", holding_brake: true" if holding_brake else ""
    path.write_text(f"""robot: {robot}
transmissions:
  yaw: {{reduction: 1, rotor_inertia: 0.002}}
defaults: {{protocol: myactuator}}
buses:
  - name: leg
    interface: zenoh
    channel: myactuator/leg
    cycle_hz: 500
    drives:
      - {{node_id: 1, joint: yaw, options: {{model: X8-20, kp: 20.0, kd: 0.5}}{brake}}}
""")
    return path


class Rmd(PlantMaster):
    """A lock-step master of the one-axis X8-20: each command closes a cycle of its own."""

    def ask(self, command: int, rest: bytes = bytes(7), can_id: int = 0x141) -> bytes | None:
        """The command's answer on 0x241 (None: none)."""
        answers = [m for m in self.send(can_id, bytes([command]) + rest)
                   if m.arbitration_id in (0x241, 0x300)]
        return bytes(answers[0].data) if answers else None

    def move(self, degrees: float, speed: int = 500) -> bytes | None:
        """0xA4 to ``degrees`` at most ``speed`` dps (§2.21.2)."""
        return self.ask(0xA4, bytes([0]) + struct.pack("<Hi", speed, round(degrees * 100)))

    @property
    def drive(self) -> MyActuatorDrive:
        return self.bench.sim.drives[0]


@pytest.fixture
def rmd(tmp_path):
    with DrivesBench(one_axis(tmp_path), lock_step=True) as bench:
        yield Rmd(bench)


# --- the codec against the document's examples -------------------------------------------

def test_status_1_reads_as_the_documents_example_14_4():
    """§2.14.4: 9A 32 00 01 E5 01 04 00 is 50 °C, brake released, 48.5 V, low voltage."""
    data = bytes.fromhex("9A320001E5010400")
    assert unpack_status_1(data) == (50, True, 48.5, ErrorState.LOW_VOLTAGE)
    assert pack_status_1(50, True, 48.5, ErrorState.LOW_VOLTAGE) == data


def test_control_replies_read_as_the_documents_examples_15_4_and_19_4():
    """§2.15.4/§2.19.4: 32 64 00 F4 01 2D 00 is 50 °C, 1 A, 500 dps, 45°; FF9C FE0C FFD3
    the negatives."""
    assert unpack_state(bytes.fromhex("9C326400F4012D00")) == MotorState(50, 1.0, 500, 45)
    assert pack_state(0xA1, MotorState(50, -1.0, -500, -45)).hex().upper() == (
        "A1329CFF0CFED3FF")


def test_motion_mode_command_reads_as_the_documents_example_5_4():
    """§5.4: E6 66 82 E0 52 33 3B 55 is p 9.99 rad, v 1.021 rad/s, kp 10.012, kd 1, t_ff
    10.004 N·m; the reply 01 E6 65 82 EB 55 names motor 1. (The example's "9.99" is its
    (58982/65536)·25 − 12.5, which is 10.000: it is shown cut to two decimals.)"""
    command = unpack_command(bytes.fromhex("E66682E052333B55"), MIT_RANGES)
    assert (command.position, command.velocity, command.kp, command.kd,
            command.torque) == pytest.approx((10.0, 1.021, 10.012, 1.0, 10.004), abs=2e-3)
    node, position, velocity, torque = unpack_mit_reply(bytes.fromhex("01E66582EB550000"))
    assert node == 1 and (position, velocity, torque) == pytest.approx((10.0, 1.021, 10.004),
                                                                       abs=2e-3)


def test_models_carry_the_sdks_figures_and_their_names_peak():
    """2b-t/myactuator_rmd actuator_constants.hpp: X8_20 6:1, 10 N·m at 5.2 A, 190 rpm."""
    x8 = model("RMD-X8-20")
    assert (x8.gear_ratio, x8.rated_torque, x8.peak_torque) == (6, 10, 20)
    assert x8.torque_constant == pytest.approx(10 / 5.2)
    assert x8.no_load_speed == pytest.approx(190 * 2 * math.pi / 60)
    assert {"X4-24", "X6-40", "X8-90", "X10-100", "X12-150"} <= set(MODELS)
    with pytest.raises(KeyError, match="no MyActuator model 'X99'"):
        model("X99")


# --- each command on a motor (lock-step) -------------------------------------------------

def test_read_and_write_pid_parameters_2_1_to_2_3(rmd):
    """§2.1-2.3: float by index; RAM lost at a restart, ROM kept (§2.2.1, §2.3.1)."""
    assert rmd.ask(0x30, bytes([1]) + bytes(6)) == bytes.fromhex("300100000000803F")
    rmd.ask(0x31, bytes([1, 0, 0]) + struct.pack("<f", 1.5))
    assert rmd.ask(0x30, bytes([1]) + bytes(6))[4:] == struct.pack("<f", 1.5)
    rmd.ask(0x32, bytes([4, 0, 0]) + struct.pack("<f", 2.5))
    rmd.ask(0x76)
    assert rmd.ask(0x30, bytes([1]) + bytes(6))[4:] == struct.pack("<f", 1.0)
    assert rmd.ask(0x30, bytes([4]) + bytes(6))[4:] == struct.pack("<f", 2.5)


def test_acceleration_reads_and_writes_by_index_2_4_and_2_5(rmd):
    """§2.4.5: 10000 dps/s read; §2.5: written by index (100-60000; hil keeps the old
    value of one outside)."""
    assert rmd.ask(0x42, bytes(7)) == bytes.fromhex("4200000010270000")
    assert rmd.ask(0x43, bytes([2, 0, 0]) + struct.pack("<I", 500)) == (
        bytes([0x43, 2, 0, 0]) + struct.pack("<I", 500))
    rmd.ask(0x43, bytes([2, 0, 0]) + struct.pack("<I", 50))
    assert rmd.ask(0x42, bytes([2]) + bytes(6))[4:] == struct.pack("<I", 500)


def test_encoder_reads_2_6_to_2_8_and_2_11_count_16384_lines_times_the_gear(rmd):
    """§2.15.4: 360° at the output is 16384 x the reduction pulses; 90° on the X8-20 (6:1)
    is 24576; the rotor's turn (§2.11) is 1.5 turns: 8192."""
    rmd.move(90)
    rmd.wait(1.0)
    assert struct.unpack_from("<i", rmd.ask(0x60), 4)[0] == pytest.approx(24576, abs=20)
    assert struct.unpack_from("<i", rmd.ask(0x61), 4)[0] == pytest.approx(24576, abs=20)
    assert struct.unpack_from("<i", rmd.ask(0x62), 4)[0] == 0
    position, raw, offset = struct.unpack_from("<HHH", rmd.ask(0x90), 2)
    assert position == raw == pytest.approx(8192, abs=20) and offset == 0


def test_zero_commands_take_effect_after_the_system_reset_2_9_2_10_2_25(rmd):
    """§2.10.1: "After writing the new zero point position, you need to send 0x76 (system
    reset command) to restart the system to be effective"; 0x76 answers nothing (§2.25.3)."""
    rmd.move(45)
    rmd.wait(0.8)
    answer = rmd.ask(0x64)
    assert struct.unpack_from("<i", answer, 4)[0] == pytest.approx(12288, abs=20)
    assert struct.unpack_from("<i", rmd.ask(0x92), 4)[0] == pytest.approx(4500, abs=5)
    assert rmd.ask(0x76) is None
    assert struct.unpack_from("<i", rmd.ask(0x92), 4)[0] == 0
    rmd.ask(0x63, bytes(3) + struct.pack("<i", 0))                 # §2.9: back to 0 pulses
    rmd.ask(0x76)
    assert struct.unpack_from("<i", rmd.ask(0x92), 4)[0] == pytest.approx(4500, abs=5)


def test_multi_turn_and_single_turn_angles_2_12_2_13(rmd):
    """§2.12: int32 0.01°; §2.13: uint16 0-35999 of the turn."""
    rmd.move(400, speed=1000)
    rmd.wait(1.5)
    assert struct.unpack_from("<i", rmd.ask(0x92), 4)[0] == pytest.approx(40000, abs=5)
    assert struct.unpack_from("<H", rmd.ask(0x94), 6)[0] == pytest.approx(4000, abs=5)


def test_status_1_2_3_report_temperature_voltage_and_currents_2_14_to_2_16(rmd):
    status = rmd.ask(0x9A)
    assert unpack_status_1(status) == (25, False, 48.0, ErrorState(0))
    rmd.ask(0xA1, bytes(3) + struct.pack("<h", 100) + bytes(2))        # 1 A
    rmd.wait(0.05)
    state = unpack_state(rmd.ask(0x9C))
    assert state.temperature == 25 and state.iq == pytest.approx(1.0) and state.speed > 0
    _, temperature, *phases = struct.unpack("<Bb3h", rmd.ask(0x9D))
    amplitude = abs(unpack_state(rmd.ask(0x9C)).iq) * 100         # the phases of iq
    assert temperature == 25 and sum(phases) == pytest.approx(0, abs=2)
    assert 0.86 * amplitude - 2 <= max(abs(p) for p in phases) <= amplitude + 2


def test_shutdown_turns_the_output_off_and_stop_holds_2_17_2_18(rmd):
    rmd.ask(0xA2, bytes(3) + struct.pack("<i", 9000))                  # 90 dps
    rmd.wait(0.5)
    assert rmd.ask(0x81) == bytes([0x81]) + bytes(7)
    here = rmd.joint()
    rmd.wait(0.5)
    assert rmd.joint() == pytest.approx(here, abs=0.01)
    assert rmd.drive.core.power is Power.ENABLED
    assert rmd.ask(0x80) == bytes([0x80]) + bytes(7)
    assert rmd.drive.core.power is Power.DISABLED
    assert rmd.ask(0x70)[7] == 0


def test_torque_speed_and_position_commands_2_19_to_2_23(rmd):
    """§2.19 0.2 A turns it; §2.20 100 dps; §2.21 to 360° at 500 dps; §2.22 the turn's 100°
    counterclockwise; §2.23 +45° from here; 0x70 names each loop (§2.24)."""
    rmd.ask(0xA1, bytes(3) + struct.pack("<h", 20) + bytes(2))
    rmd.wait(0.1)
    assert rmd.joint() > 0.01 and rmd.ask(0x70)[7] == 1
    rmd.ask(0xA2, bytes(3) + struct.pack("<i", 10000))
    rmd.wait(1.0)
    assert unpack_state(rmd.ask(0x9C)).speed == pytest.approx(100, abs=2)
    assert rmd.ask(0x70)[7] == 2
    rmd.move(360)
    rmd.wait(2.0)
    assert rmd.joint() == pytest.approx(2 * math.pi, abs=0.01) and rmd.ask(0x70)[7] == 3
    answer = rmd.ask(0xA6, bytes([1]) + struct.pack("<HH", 500, 10000) + bytes(2))
    assert answer[0] == 0xA6
    rmd.wait(2.0)
    assert rmd.joint() == pytest.approx(100 * DEG, abs=0.01)         # 360° -> 100°, -260°
    rmd.ask(0xA8, bytes([0]) + struct.pack("<Hi", 500, 4500))
    rmd.wait(1.0)
    assert rmd.joint() == pytest.approx(145 * DEG, abs=0.01)


def test_brake_lock_stops_the_motor_and_torque_needs_the_brake_released_2_19_2_26_2_27(
        tmp_path):
    """§2.19.1: 0xA1 "cannot open the brake directly"; 0x77 releases (status 1's byte 3),
    0x78 locks: "the motor can no longer run"."""
    with DrivesBench(one_axis(tmp_path, holding_brake=True), lock_step=True) as bench:
        rmd = Rmd(bench)
        rmd.ask(0xA1, bytes(3) + struct.pack("<h", 20) + bytes(2))
        rmd.wait(0.2)
        assert rmd.joint() == pytest.approx(0, abs=1e-3)
        assert rmd.ask(0x77) == bytes([0x77]) + bytes(7) and rmd.ask(0x9A)[3] == 1
        rmd.ask(0xA1, bytes(3) + struct.pack("<h", 20) + bytes(2))
        rmd.wait(0.1)
        assert rmd.joint() > 0.01
        rmd.ask(0x78)
        assert rmd.drive.core.power is Power.DISABLED and rmd.ask(0x9A)[3] == 0


def test_runtime_version_baud_model_and_active_reply_2_28_to_2_33(rmd):
    rmd.wait(0.2)
    assert struct.unpack_from("<I", rmd.ask(0xB1), 4)[0] >= 0
    assert rmd.ask(0xB2) == bytes.fromhex("B20000002E893401")         # §2.29.4: 20220206
    assert rmd.ask(0xB4, bytes(6) + bytes([1])) == bytes([0xB4]) + bytes(6) + bytes([1])
    assert rmd.ask(0xB5)[1:] == b"X8-20  "
    assert rmd.ask(0xB6, bytes([0x60, 1, 1, 0, 0, 0, 0])) is None     # §2.33.3


def test_function_control_2_34_filter_and_angle_limits(rmd):
    """Index 2: with the CANID filter on, 0x280 is not heard; indexes 6/7 bound the
    position modes (0.01°, hil's reading)."""
    assert rmd.ask(0x20, bytes([6, 0, 0]) + struct.pack("<i", 3000)) == (
        bytes([0x20, 6, 0, 0]) + struct.pack("<i", 3000))
    rmd.move(90)
    rmd.wait(1.0)
    assert rmd.joint() == pytest.approx(30 * DEG, abs=0.01)
    rmd.ask(0x20, bytes([2, 0, 0]) + struct.pack("<i", 1))
    assert rmd.ask(0x9A, can_id=0x280) is None


def test_multi_motor_command_is_answered_on_each_motors_reply_id_3(rmd):
    """§3.2: 0x280 0x80, each motor answers on 0x240 + its id."""
    rmd.ask(0xA2, bytes(3) + struct.pack("<i", 9000))
    assert rmd.ask(0x80, can_id=0x280) == bytes([0x80]) + bytes(7)
    assert rmd.drive.core.power is Power.DISABLED


def test_canid_read_and_write_on_0x300_4(rmd):
    """§4.4: the read answers 0x241 in bytes 6-7 on 0x300; a write takes effect at the next
    start (0x20 index 5: "after a reboot"), then the motor answers on 0x242."""
    answers = rmd.send(0x300, bytes([0x79, 0, 1, 0, 0, 0, 0, 0]))
    assert [(m.arbitration_id, bytes(m.data).hex()) for m in answers] == [
        (0x300, "7900010000004102")]
    rmd.send(0x300, bytes([0x79, 0, 0, 0, 0, 0, 0, 2]))
    assert rmd.ask(0x9A) is not None
    rmd.ask(0x76)
    assert rmd.ask(0x9A) is None
    assert [m.arbitration_id for m in rmd.send(0x142, bytes([0x9A]) + bytes(7))] == [0x242]


def test_motion_mode_follows_p_v_kp_kd_t_and_answers_on_0x500_plus_id_5(rmd):
    from hil.protocols.mit import MitCommand, pack_command

    for _ in range(500):
        answers = rmd.send(0x401, pack_command(MitCommand(0.5, 0, 20.0, 0.5, 0), MIT_RANGES))
    assert [m.arbitration_id for m in answers] == [0x501]
    node, position, _, _ = unpack_mit_reply(bytes(answers[0].data))
    assert node == 1 and position == pytest.approx(0.5, abs=0.01)


# --- hil's side: init, describe, its master, replay ---------------------------------------

def test_hil_init_with_a_model_writes_its_figures(tmp_path):
    from hil.cli import main

    output = tmp_path / "one.yaml"
    assert main(["init", str(URDF), "--protocol", "myactuator", "--motor", "X8-20", "-o",
                 str(output)]) == 0
    drive = load_bus_config(output).drives[0]
    assert drive.options.model is MODELS["X8-20"] and drive.options.kp > 0
    assert (drive.peak_torque, drive.holding_brake, drive.watchdog_timeout) == (20, False, 0)


def test_hil_describe_lists_every_frame_in_the_familys_words(tmp_path, capsys):
    from hil.cli import main

    assert main(["describe", str(one_axis(tmp_path))]) == 0
    out = capsys.readouterr().out
    for words in ("motion mode control command", "motion mode reply", "single motor command",
                  "multi-motor command", "CANID setting command", "0xA4 absolute position",
                  "0x9A read status 1", "0xB3 can timeout"):
        assert words in out, words


def test_frame_source_tells_commands_replies_and_the_canid_reply():
    drives = {1: MyActuatorOptions()}
    source = MyActuator.frame_source
    from hil.can.frame import Frame

    assert source(Frame(0x141, bytes([0xA4]) + bytes(7)), drives).what == (
        "0xA4 absolute position")
    assert source(Frame(0x241, bytes([0x9A]) + bytes(7)), drives).sender.value == "drive"
    assert source(Frame(0x300, bytes.fromhex("7900010000004102")), drives).node_id == 1
    assert source(Frame(0x300, bytes.fromhex("7900010000000000")), drives).cycle
    assert source(Frame(0x142, bytes(8)), drives) is None


def test_hils_master_drives_rmd_motors_in_motion_mode_lock_step(tmp_path):
    from hil.controllers import GoalStatus

    result, position = hils_master_moves(one_axis(tmp_path), "yaw", 0.5)
    assert result.status is GoalStatus.SUCCEEDED, result
    assert position == pytest.approx(0.5, abs=0.01)


@pytest.mark.slow
def test_a_lock_step_log_replays_bit_for_bit(tmp_path, capsys):
    from test_replay import lock_step_log, replay

    config = one_axis(tmp_path)
    log = lock_step_log(config, tmp_path)
    capsys.readouterr()
    status, out = replay(capsys, log, config)
    assert status == 0, out
    assert "0 divergences: every answer as logged, bit for bit" in out
