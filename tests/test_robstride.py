"""Robstride RS00-RS06 and Xiaomi CyberGear actuators as their makers document them: a test
per message of the private protocol (the CyberGear instruction manual §4.1, section numbers
below; the RS types 22-25 as RobStride/SampleProgram ``RS/Robstride01.cpp`` sends them) and
of the RS MIT protocol mode (the RS00 manual 260112, MIT chapter, command numbers), the
special frames sent ten times to an enabled motor, frames of the wrong framing, a lock-step
replay, ``hil init``/``hil describe``, hil's own master, and two published clients driving
the motors through their own sequences: LeRobot 0.4.4's ``RobstrideMotorsBus`` (the MIT
protocol mode it is written for) and kscale's ``robstride`` 0.1.0 (the private protocol,
pinned in the test extra)."""

from __future__ import annotations

import logging
import math
import re
import struct
import time
from pathlib import Path

import can
import pytest

from conftest import TESTS, hils_master_moves
from hil.bus_config import load_bus_config
from hil.cli import main
from hil.protocols.robstride import RobstrideOptions
from hil.protocols.robstride import params as P
from hil.protocols.robstride.codec import (
    Comm, Fault, Feedback, Motion, MotorMode, Ranges, pack_feedback, pack_mit_answer,
    pack_motion, private_id, unpack_feedback, unpack_mit_answer, unpack_motion,
)
from hil.protocols.robstride.models import MODELS, model
from hil.testing import DrivesBench

URDF = TESTS / "fixtures" / "damiao_one_axis.urdf"
HOST = 0xFD
#: the CyberGear's ranges (§4.1.2)
CYBERGEAR = Ranges(4 * math.pi, 30.0, 12.0, 500.0, 5.0)
HOLD = 0.05                          # rad: how far a special frame may let the joint drift


def config(tmp_path: Path, options: str, drive: str = "") -> Path:
    """One Robstride motor (node 1) on the Damiao tests' vertical axis (no gravity about
    it), its output shaft on the joint."""
    path = tmp_path / "robstride.yaml"
    path.write_text(f"""robot: {URDF}
transmissions:
  yaw: {{reduction: 1, rotor_inertia: 0.002}}
defaults: {{protocol: robstride}}
buses:
  - name: legs
    interface: zenoh
    channel: robstride/legs
    cycle_hz: 500
    drives:
      - {{node_id: 1, joint: yaw, {drive} options: {{{options}}}}}
""")
    return path


class Master:
    """A master's bus on a lock-step bench: each frame is a cycle, its answers read after."""

    def __init__(self, bench: DrivesBench):
        self.bench, self.bus = bench, bench.bus("legs")

    def ask(self, identifier: int, data: bytes = bytes(8), extended: bool = True
            ) -> list[can.Message]:
        self.bus.send(can.Message(arbitration_id=identifier, data=data,
                                  is_extended_id=extended))
        self.bench.step()
        return list(iter(lambda: self.bus.recv(0), None))

    def request(self, comm: Comm, data: bytes = bytes(8), node: int = 1, field: int = HOST
                ) -> list[can.Message]:
        return self.ask(private_id(comm, field, node), data)

    def wait(self, cycles: int) -> None:
        self.bench.step(cycles)

    @property
    def drive(self):
        return self.bench.sim.drives[0]

    def joint(self) -> float:
        return self.bench.joint("yaw")


@pytest.fixture
def rs03(tmp_path):
    with DrivesBench(config(tmp_path, "model: RS03, kp: 40.0, kd: 2.0"), lock_step=True) as b:
        yield Master(b)


@pytest.fixture
def cybergear(tmp_path):
    with DrivesBench(config(tmp_path, "model: CyberGear, kp: 10.0, kd: 0.5"),
                     lock_step=True) as bench:
        yield Master(bench)


@pytest.fixture
def mit_rs00(tmp_path):
    with DrivesBench(config(tmp_path, "model: RS00, protocol: mit, kp: 10.0, kd: 0.5"),
                     lock_step=True) as bench:
        yield Master(bench)


def feedback(message: can.Message, ranges: Ranges) -> Feedback:
    assert message.is_extended_id and message.arbitration_id >> 24 == Comm.FEEDBACK
    return unpack_feedback(message.arbitration_id, message.data, ranges)


def rs03_ranges() -> Ranges:
    return RobstrideOptions(MODELS["RS03"]).ranges()


def write(master: Master, index: int, value: float) -> list[can.Message]:
    return master.request(Comm.WRITE_PARAMETER,
                          P.parameter_frame(index, P.TABLE[index].pack(value)))


def move_in_operation_control(master: Master, target: float, ranges: Ranges) -> None:
    master.request(Comm.ENABLE)
    identifier, data = pack_motion(Motion(target, 0.0, 40.0, 2.0, 0.0), ranges, 1)
    for _ in range(300):
        master.ask(identifier, data)


# --- the codec (§4.1.2, §4.1.3; RS00 MIT §5.1) ------------------------------------------

def test_motion_control_carries_the_torque_in_the_id_and_four_big_endian_uint16():
    """§4.1.2: id bits 23-8 the torque over ±12 N·m; bytes 0-7 angle ±4π, speed ±30 rad/s,
    Kp 0-500, Kd 0-5, as the manual's ``motor_controlmode`` packs them."""
    identifier, data = pack_motion(Motion(0.0, 0.0, 250.0, 5.0, 12.0), CYBERGEAR, 127)
    assert identifier == 1 << 24 | 0xFFFF << 8 | 127
    assert data.hex() == "7fff7fff7fffffff"
    back = unpack_motion(identifier, data, CYBERGEAR)
    assert (back.torque, back.kd) == (12.0, 5.0)


def test_feedback_carries_mode_faults_and_ids_in_the_id_and_temperature_x10():
    """§4.1.3: bits 23-22 the mode (2 run), 21-16 the faults, 15-8 the motor, 7-0 the host;
    bytes 6-7 the temperature x 10."""
    identifier, data = pack_feedback(Feedback(5, 0.0, 0.0, 0.0, 31.5, MotorMode.RUN,
                                              Fault.OVER_TEMPERATURE), CYBERGEAR, HOST)
    assert identifier == 2 << 24 | 2 << 22 | 4 << 16 | 5 << 8 | HOST
    assert data[6:] == struct.pack(">H", 315)
    assert unpack_feedback(identifier, data, CYBERGEAR).faults is Fault.OVER_TEMPERATURE


def test_the_mit_answer_is_the_rs00_manuals_layout():
    """RS00 MIT §5.1: id, angle 16, speed 12, torque 12, temperature x 10 in 16 bits."""
    ranges = Ranges(12.57, 33.0, 14.0, 500.0, 5.0)
    data = pack_mit_answer(Feedback(1, 0.0, 0.0, 0.0, 25.0), ranges)
    assert data.hex() == "017fff7ff7ff00fa"
    assert unpack_mit_answer(data, ranges).temperature == 25.0


def test_each_model_has_its_documents_ranges_and_the_cybergear_its_own():
    assert (model("rs-03").v_max, model("RS03").t_max, model("RS03").kp_max) == (50, 60, 5000)
    assert (model("RS00").v_max, model("RS00").t_max) == (33, 14)
    found = model("cybergear")
    assert (found.p_max, found.v_max, found.t_max, found.cybergear) == (4 * math.pi, 30, 12,
                                                                        True)


def test_options_refuse_mit_on_a_cybergear_and_gains_beyond_the_model():
    with pytest.raises(ValueError, match="no MIT protocol mode"):
        RobstrideOptions.from_mapping({"model": "CyberGear", "protocol": "mit"})
    with pytest.raises(ValueError, match="'kp' must be in"):
        RobstrideOptions.from_mapping({"model": "RS00", "kp": 600})
    assert RobstrideOptions.from_mapping({"model": "RS03", "kp": 600}).kp == 600


# --- the private protocol's messages (§4.1) ----------------------------------------------

def test_get_device_id_answers_type_0_from_the_motor_to_0xfe_with_the_mcu_id(rs03):
    """§4.1.1."""
    (answer,) = rs03.request(Comm.GET_DEVICE_ID)
    assert answer.arbitration_id == private_id(Comm.GET_DEVICE_ID, 1, 0xFE)
    assert len(answer.data) == 8


def test_enable_answers_feedback_in_run_mode_to_the_requesting_host(rs03):
    """§4.1.4: answered with type 2; the host is the request's bits 15-8."""
    (answer,) = rs03.request(Comm.ENABLE, field=0xAA)
    assert answer.arbitration_id & 0xFF == 0xAA
    assert feedback(answer, rs03_ranges()).mode is MotorMode.RUN
    # type 1's bits 15-8 are its torque's, no host: answered to the last host heard
    (answer,) = rs03.ask(*pack_motion(Motion(0.0, 0.0, 0.0, 0.0, 1.0), rs03_ranges(), 1))
    assert answer.arbitration_id & 0xFF == 0xAA


def test_motion_control_moves_the_motor_in_operation_control_mode(rs03):
    """§4.1.2, §4.2.2: enable, then type 1 commands."""
    move_in_operation_control(rs03, 0.5, rs03_ranges())
    assert rs03.joint() == pytest.approx(0.5, abs=0.02)


def test_stop_releases_the_motor_and_byte_0_set_to_1_clears_a_fault(rs03):
    """§4.1.5; a drive fault hil injects is the RS stall overload (feedback bit 20)."""
    rs03.request(Comm.ENABLE)
    rs03.bench.fault("yaw")
    rs03.wait(2)
    (answer,) = rs03.request(Comm.STOP)
    assert feedback(answer, rs03_ranges()).faults is Fault.STALL_OVERLOAD
    (answer,) = rs03.request(Comm.STOP, bytes([1]) + bytes(7))
    found = feedback(answer, rs03_ranges())
    assert (found.faults, found.mode) == (Fault(0), MotorMode.RESET)


def test_set_zero_makes_here_zero_and_moves_nothing(rs03):
    """§4.1.6: byte 0 = 1; lost at a power cycle."""
    move_in_operation_control(rs03, 0.5, rs03_ranges())
    before = rs03.joint()
    (answer,) = rs03.request(Comm.SET_ZERO, bytes([1]) + bytes(7))
    rs03.wait(100)
    assert feedback(answer, rs03_ranges()).position == pytest.approx(0.0, abs=1e-3)
    assert rs03.joint() == pytest.approx(before, abs=0.01)
    rs03.bench.fault("yaw", "restart")
    (answer,) = rs03.request(Comm.ENABLE)
    assert feedback(answer, rs03_ranges()).position == pytest.approx(before, abs=0.01)


def test_set_can_id_takes_effect_at_once_and_answers_type_0_from_the_new_id(rs03):
    """§4.1.7: the new id in bits 23-16."""
    (answer,) = rs03.request(Comm.SET_CAN_ID, field=5 << 8 | HOST)
    assert answer.arbitration_id == private_id(Comm.GET_DEVICE_ID, 5, 0xFE)
    assert rs03.request(Comm.ENABLE) == []
    (answer,) = rs03.request(Comm.ENABLE, node=5)
    assert answer.arbitration_id >> 8 & 0xFF == 5


def test_parameters_read_and_write_little_endian_and_an_unknown_one_answers_status_1(rs03):
    """§4.1.8, §4.1.9: index in bytes 0-1, value in 4-7; a write is answered with type 2."""
    (answer,) = write(rs03, P.LIMIT_SPD, 7.5)
    assert answer.arbitration_id >> 24 == Comm.FEEDBACK
    (answer,) = rs03.request(Comm.READ_PARAMETER, P.parameter_frame(P.LIMIT_SPD))
    assert answer.arbitration_id == private_id(Comm.READ_PARAMETER, 1, HOST)
    assert struct.unpack_from("<Hxxf", answer.data) == (P.LIMIT_SPD, 7.5)
    (answer,) = rs03.request(Comm.READ_PARAMETER, P.parameter_frame(0x7777))
    assert answer.arbitration_id >> 16 & 0xFF == 1


@pytest.mark.parametrize("run_mode, index, value", [
    (5, P.LOC_REF, 0.4), (1, P.LOC_REF, 0.4), (2, P.SPD_REF, 2.0), (3, P.IQ_REF, 0.1)],
    ids=["csp", "pp", "speed", "current"])
def test_each_run_mode_follows_its_reference_after_the_manuals_sequence(rs03, run_mode,
                                                                        index, value):
    """§4.2.3-4.2.5: run_mode, enable, the limit, the reference."""
    write(rs03, P.RUN_MODE, run_mode)
    rs03.request(Comm.ENABLE)
    write(rs03, P.LIMIT_SPD, 5.0)
    write(rs03, P.LIMIT_CUR, 10.0)
    write(rs03, index, value)
    if index == P.LOC_REF:
        rs03.wait(500)
        assert rs03.joint() == pytest.approx(value, abs=0.02)
    else:
        rs03.wait(100)                               # 0.2 s: turning forward, short of 3 rad
        assert 0.1 < rs03.joint() < 2.0


def test_fault_feedback_answers_the_fault_word_and_warnings(rs03):
    """§4.1.10: bytes 0-3 the faults, 4-7 the warnings; a stall overload is bit 14."""
    assert rs03.request(Comm.FAULT_FEEDBACK)[0].data == bytes(8)
    rs03.bench.fault("yaw")
    rs03.wait(2)
    (answer,) = rs03.request(Comm.FAULT_FEEDBACK)
    assert struct.unpack("<II", answer.data) == (1 << 14, 0)


def test_save_keeps_the_parameters_through_a_power_cycle_and_unsaved_ones_are_lost(rs03):
    """Type 22 (SampleProgram ``MotorDataSave``); §4.1.9: a write is lost at power-off."""
    write(rs03, P.LIMIT_SPD, 7.0)
    rs03.request(Comm.SAVE_PARAMETERS, bytes(range(1, 9)))
    write(rs03, P.LIMIT_CUR, 3.0)
    rs03.bench.fault("yaw", "restart")
    assert (rs03.drive.values[P.LIMIT_SPD], rs03.drive.values[P.LIMIT_CUR]) == (7.0, 23.0)


def test_a_baud_rate_change_takes_effect_at_the_next_power_cycle(rs03, caplog):
    """Type 23, byte 6 (SampleProgram ``BaudRateChange``: "after a power cycle"): at 500
    kbit/s the motor is no longer on this 1 Mbit/s bus."""
    (answer,) = rs03.request(Comm.BAUD_RATE, bytes([1, 2, 3, 4, 5, 6, 2, 8]))
    assert answer.arbitration_id >> 24 == Comm.GET_DEVICE_ID
    assert rs03.request(Comm.ENABLE)
    rs03.bench.fault("yaw", "restart")
    with caplog.at_level(logging.WARNING):
        assert rs03.request(Comm.ENABLE) == []
    assert "bus 'legs'" in caplog.text


def test_active_reporting_sends_feedback_every_10_ms_until_turned_off(rs03):
    """Type 24, byte 6 (SampleProgram ``ProactiveEscalationSet``: "default period 10 ms")."""
    drive = rs03.drive
    assert rs03.request(Comm.ACTIVE_REPORTING, bytes([1, 2, 3, 4, 5, 6, 1, 8])) == []
    # ticks of a clock of the test's, ahead of the simulator's own (which then sends none)
    later = time.monotonic() + 1000.0
    with rs03.bench.sim.lock:
        while rs03.bus.recv(0) is not None:          # what the simulator's ticks sent
            pass
        for tick in range(50):                        # 50 ms
            drive.tick(later + 0.0005 + tick * 0.001)
    reports = list(iter(lambda: rs03.bus.recv(0), None))
    assert len(reports) == 5 and all(m.arbitration_id >> 24 == Comm.FEEDBACK for m in reports)
    rs03.request(Comm.ACTIVE_REPORTING, bytes([1, 2, 3, 4, 5, 6, 0, 8]))
    with rs03.bench.sim.lock:
        drive.tick(later + 1.0)
    assert rs03.bus.recv(0) is None


def test_the_protocol_switch_takes_effect_after_a_power_cycle(rs03):
    """Type 25, byte 6 = 2 (MIT): still private until the power cycle (SampleProgram README:
    "then power-cycle the motor"), then 11-bit frames only."""
    enable = bytes([0xFF] * 7 + [0xFC])
    rs03.request(Comm.PROTOCOL, bytes([1, 2, 3, 4, 5, 6, 2, 8]))
    assert rs03.request(Comm.ENABLE)
    assert rs03.ask(0x001, enable, extended=False) == []
    rs03.bench.fault("yaw", "restart")
    (answer,) = rs03.ask(0x001, enable, extended=False)
    assert (answer.arbitration_id, answer.data[0]) == (HOST, 1)
    assert rs03.request(Comm.ENABLE) == []


def test_a_cybergear_takes_type_22_as_its_baud_rate_and_knows_no_later_type(cybergear):
    """CyberGear §4.1.11: type 22, byte 0 the rate, answered with type 0; types 23-25 are
    not in its manual (and not answered)."""
    (answer,) = cybergear.request(Comm.SAVE_PARAMETERS, bytes([2]) + bytes(7))
    assert answer.arbitration_id >> 24 == Comm.GET_DEVICE_ID
    for comm in (Comm.BAUD_RATE, Comm.ACTIVE_REPORTING, Comm.PROTOCOL):
        assert cybergear.request(comm, bytes([1, 2, 3, 4, 5, 6, 2, 8])) == []
    move_in_operation_control(cybergear, 0.3, CYBERGEAR)
    assert cybergear.joint() == pytest.approx(0.3, abs=0.02)


# --- hil's side: init, describe, replay, its master --------------------------------------

def test_hil_init_with_a_model_writes_it_and_its_figures(tmp_path):
    output = tmp_path / "one.yaml"
    assert main(["init", str(URDF), "--protocol", "robstride", "--motor", "RS03", "-o",
                 str(output)]) == 0
    drive = load_bus_config(output).drives[0]
    assert drive.options.model is MODELS["RS03"]
    assert (drive.peak_torque, drive.holding_brake) == (60, False)     # the RS03's


def test_hil_describe_lists_every_frame_in_the_makers_words(tmp_path, capsys):
    assert main(["describe", str(config(tmp_path, "model: RS03, kp: 40.0, kd: 2.0"))]) == 0
    out = capsys.readouterr().out
    for what in ("motion control", "feedback", "device id", "enable", "stop",
                 "set mechanical zero", "set CAN id", "read parameter", "write parameter",
                 "fault request", "save parameters", "baud rate", "active reporting",
                 "protocol switch"):
        assert what in out, what


def test_a_lock_step_log_replays_bit_for_bit(tmp_path, capsys):
    path = config(tmp_path, "model: RS03, kp: 40.0, kd: 2.0")
    with DrivesBench(path, lock_step=True) as bench:
        folder = tmp_path / "logs"
        bench.log_to(folder)
        master = Master(bench)
        write(master, P.LIMIT_SPD, 3.0)
        move_in_operation_control(master, 0.4, rs03_ranges())
        deadline = time.monotonic() + 30      # the logs' listeners drained (a condition)
        while any(not listener.queue.empty() for _, listener in bench._logs) \
                and time.monotonic() < deadline:
            time.sleep(0.01)
    status = main(["replay", str(folder), str(path), "--clock", "cycles"])
    out = capsys.readouterr()
    text = out.out + out.err
    assert status == 0, text
    assert "0 divergences: every answer as logged, bit for bit" in text
    assert int(re.search(r"(\d+) answers compared", text).group(1)) >= 300


def test_hils_master_drives_a_robstride_motor_in_operation_control(tmp_path):
    from hil.controllers import GoalStatus

    result, position = hils_master_moves(config(tmp_path, "model: RS03, kp: 40.0, kd: 2.0"),
                                         "yaw", 0.5)
    assert result.status is GoalStatus.SUCCEEDED, result
    assert position == pytest.approx(0.5, abs=0.02)
