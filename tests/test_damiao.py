"""Damiao DM-J motors as the maker's firmware speaks: the codec against the maker's layout,
the special frames (none of them moves a motor), the registers, the lost-communication
state, and published client libraries driving a simulated motor through their README's
sequence (python ``damiao-motor``, pinned in the test extra).

Sources: the DM-J manuals' CAN protocol as Damiao's sample code ``DM_CAN.py`` implements it
(special frames FF x 7 + FC/FD/FE/FB, mode ids 0x100/0x200/0x300 + id, registers on 0x7FF,
``Limit_Param``), and the feedback layout python ``damiao-motor`` documents (its
communication-protocol page: D0 state << 4 | id, D6 MOSFET and D7 rotor temperature)."""

from __future__ import annotations

import struct
import threading
import time

import pytest

from conftest import (
    TEST_MOTOR_DRIVE, TESTS, RealTimeMaster, hils_master_moves, socketcan_missing,
)
from hil.bus_config import load_bus_config
from hil.drives import DriveCore, DriveParameters, Power
from hil.protocols.damiao import (
    CLEAR_ERROR, DISABLE, ENABLE, SAVE_ZERO, ControlMode, DamiaoOptions, Feedback, State,
    pack_feedback, unpack_feedback,
)
from hil.protocols.damiao.drive import DamiaoDrive
from hil.protocols.damiao.models import MODELS, model
from hil.protocols.mit import MitCommand, MitRanges, pack_command
from hil.testing import DrivesBench
from test_mit_profile import LockStep, PlantMaster, drive_config

#: judged against the host's stalls (tests/host_stalls.py): the drives run in real time beside
#: the client libraries
pytestmark = pytest.mark.real_time

CONFIG = TESTS / "fixtures" / "damiao_one_axis.yaml"
DM4310 = MitRanges(12.5, 30.0, 500.0, 5.0, 10.0)
#: one LSB of the feedback's position: 16 bits over [-PMAX, PMAX]
POSITION_LSB = 25.0 / 65535


# --- the codec ------------------------------------------------------------------------

def test_feedback_carries_state_and_id_in_d0_and_the_temperatures_last():
    # position 0 -> 32767 (7FFF), velocity 0 -> 2047 (7FF), torque 0 -> 2047: the
    # mini-cheetah packing of the maker's sample code, state ENABLED (1), motor 1
    data = pack_feedback(Feedback(1, State.ENABLED, 0.0, 0.0, 0.0, 31, 40), DM4310)
    assert data.hex().upper() == "117FFF7FF7FF1F28"
    lost = unpack_feedback(bytes.fromhex("D37FFF7FF7FF1F28"), DM4310)
    assert (lost.motor_id, lost.state, lost.mos_temperature) == (3, State.LOST_COMMUNICATION, 31)


def test_the_special_frames_are_the_makers():
    assert [frame.hex().upper() for frame in (ENABLE, DISABLE, SAVE_ZERO, CLEAR_ERROR)] == [
        "FFFFFFFFFFFFFF" + last for last in ("FC", "FD", "FE", "FB")]


def test_each_model_maps_with_the_makers_limit_param():
    # Damiao's DM_CAN.py: 4310 [12.5, 30, 10], 4310_48 [12.5, 50, 10], 4340 [12.5, 8, 28],
    # 4340_48 [12.5, 10, 28], 6006 [12.5, 45, 20], 8006 [12.5, 45, 40], 8009 [12.5, 45, 54],
    # 10010L [12.5, 25, 200], 10010 [12.5, 20, 200]
    expected = {"DM4310": (12.5, 30, 10), "DM4310_48V": (12.5, 50, 10), "DM4340": (12.5, 8, 28),
                "DM4340_48V": (12.5, 10, 28), "DM6006": (12.5, 45, 20),
                "DM8006": (12.5, 45, 40), "DM8009": (12.5, 45, 54),
                "DM10010L": (12.5, 25, 200), "DM10010": (12.5, 20, 200)}
    for name, ranges in expected.items():
        found = MODELS[name]
        assert (found.p_max, found.v_max, found.t_max) == ranges, name
    assert model("dm-j4340") is MODELS["DM4340"] and model("4310") is MODELS["DM4310"]


def test_options_name_the_model_and_refuse_an_unknown_one():
    options = DamiaoOptions.from_mapping({"model": "DM4340", "control_mode": "velocity"})
    assert options.ranges().v_max == 8 and options.control_mode is ControlMode.VELOCITY
    assert options.drive_defaults()["peak_torque"] == 27
    with pytest.raises(ValueError, match="no Damiao model 'DM9999'"):
        DamiaoOptions.from_mapping({"model": "DM9999"})


# --- a simulated motor on a bus -------------------------------------------------------

@pytest.fixture
def master(hil_drives):
    """The DM4310 of tests/fixtures/damiao_one_axis.yaml, and a master's bus beside it."""
    return RealTimeMaster(hil_drives(CONFIG))


def test_every_frame_is_answered_with_8_bytes_of_feedback_on_the_master_id(master):
    reply = master.ask(0x001, ENABLE)
    assert reply.arbitration_id == 0x11 and len(reply.data) == 8
    assert reply.data[0] == (State.ENABLED << 4) | 1
    assert reply.data[6] == reply.data[7] == 25                     # °C: no heating modelled


@pytest.mark.parametrize("special", [CLEAR_ERROR, SAVE_ZERO, DISABLE, ENABLE],
                         ids=["clear-error", "save-zero", "disable", "enable"])
def test_no_special_frame_moves_an_enabled_motor(master, special):
    """Issue 42: hil took FF x 7 FB for an MIT command at full scale (1.0 -> 4.6 rad in
    20 ms). The maker: FB clears an error, FE saves the zero, FD disables, FC enables; none
    is a setpoint."""
    master.ask(0x001, ENABLE)
    hold = pack_command(MitCommand(master.joint(), 0.0, 20.0, 0.5, 0.0), DM4310)
    master.ask(0x001, hold)
    time.sleep(0.2)
    before = master.joint()
    for _ in range(10):
        master.ask(0x001, special)
    time.sleep(0.3)
    assert master.joint() == pytest.approx(before, abs=0.01)


def test_a_command_of_another_mode_moves_nothing(master):
    master.ask(0x001, ENABLE)
    before = master.joint()
    reply = master.ask(0x201, struct.pack("<f", 5.0) + bytes(4))      # VEL, CTRL_MODE is MIT
    time.sleep(0.3)
    assert reply is not None and master.joint() == pytest.approx(before, abs=0.01)


def test_registers_read_write_and_the_control_mode_takes_effect(master):
    read = master.ask(0x7FF, bytes([1, 0, 0x33, 10, 0, 0, 0, 0]))
    assert bytes(read.data) == bytes([1, 0, 0x33, 10]) + struct.pack("<I", 1)   # MIT
    assert read.arbitration_id == 0x11
    pmax = master.ask(0x7FF, bytes([1, 0, 0x33, 21, 0, 0, 0, 0]))
    assert struct.unpack("<f", bytes(pmax.data[4:]))[0] == pytest.approx(12.5)
    wrote = master.ask(0x7FF, bytes([1, 0, 0x55, 10]) + struct.pack("<I", 3))   # VEL
    assert bytes(wrote.data) == bytes([1, 0, 0x55, 10]) + struct.pack("<I", 3)
    master.ask(0x001, ENABLE)
    master.ask(0x201, struct.pack("<f", 2.0) + bytes(4))
    time.sleep(0.4)
    assert master.drive.core.status().velocity == pytest.approx(2.0, abs=0.2)
    master.ask(0x201, struct.pack("<f", 0.0) + bytes(4))


def test_a_register_write_it_cannot_take_leaves_it_and_answers_what_it_kept(master):
    wrote = master.ask(0x7FF, bytes([1, 0, 0x55, 10]) + struct.pack("<I", 9))
    assert struct.unpack("<I", bytes(wrote.data[4:]))[0] == 1
    other = master.ask(0x7FF, bytes([2, 0, 0x33, 10, 0, 0, 0, 0]), timeout=0.3)
    assert other is None                                      # motor 2 is not on this bus


def test_silence_past_the_timeout_is_lost_communication_until_cleared(master):
    master.ask(0x7FF, bytes([1, 0, 0x55, 9]) + struct.pack("<I", 2000))     # 2000 x 50 us
    master.ask(0x001, ENABLE)
    master.ask(0x001, pack_command(MitCommand(master.joint(), 0, 10.0, 0.3, 0), DM4310))
    time.sleep(0.4)                                            # the watchdog: 0.1 s
    reply = master.ask(0x7FF, bytes([1, 0, 0xCC, 0, 0, 0, 0, 0]))           # refresh
    assert reply.data[0] >> 4 == State.LOST_COMMUNICATION
    assert master.drive.core.power is not Power.ENABLED
    assert master.ask(0x001, ENABLE).data[0] >> 4 == State.LOST_COMMUNICATION   # not cleared
    assert master.ask(0x001, CLEAR_ERROR).data[0] >> 4 == State.DISABLED
    assert master.ask(0x001, ENABLE).data[0] >> 4 == State.ENABLED


# --- what a master writes never moves the motor where the firmware would not, lock-step ----
# (the DM4310's firmware, recovered in github.com/umeow0716/damiao_firmware:
# app/src/parameter_protocol.c write_register, app/src/app_commands.c, motor_control.c)

@pytest.fixture
def dm4310():
    """A master of the fixture's DM4310 on its plant, lock-step, TIMEOUT off; the motor
    enabled in MIT mode, held at rest at 0 rad."""
    with DrivesBench(CONFIG, lock_step=True) as bench:
        master = PlantMaster(bench)
        master.send(0x7FF, write(9, 0))
        master.send(0x001, ENABLE)
        master.send(0x001, pack_command(MitCommand(0.0, 0.0, 20.0, 0.5, 0.0), DM4310))
        master.wait(0.5)
        yield master


def write(register: int, value: float, kind: str = "<I") -> bytes:
    return bytes([1, 0, 0x55, register]) + struct.pack(kind, value)


#: at rest in each mode, with fields that would move the motor read as another mode's: an
#: MIT hold with a velocity of 5 rad/s and no damping; velocity 0; a position-velocity move
#: to where it is at 5 rad/s; a force-position move 2 rad away with no torque
AT_REST = {ControlMode.MIT: (0x001, pack_command(MitCommand(0.0, 5.0, 20.0, 0.0, 0.0), DM4310)),
           ControlMode.POSITION_VELOCITY: (0x101, struct.pack("<ff", 0.0, 5.0)),
           ControlMode.VELOCITY: (0x201, struct.pack("<f", 0.0) + bytes(4)),
           ControlMode.FORCE_POSITION: (0x301, struct.pack("<fHH", 2.0, 500, 0))}


@pytest.mark.parametrize("before, after", [(a, b) for a in ControlMode for b in ControlMode
                                           if a is not b], ids=lambda mode: mode.name)
def test_a_control_mode_change_takes_no_stale_field_as_a_command(dm4310, before, after):
    """Issue 65: CTRL_MODE 3 written to an enabled motor turned it at the last MIT command's
    velocity (5 rad/s, 3 rad in 1 s). The firmware takes the write while enabled and zeroes
    its command (write_register, register 0x0A), so the new mode runs a zeroed command."""
    dm4310.send(0x7FF, write(10, before))
    dm4310.send(*AT_REST[before])
    dm4310.wait(0.1)
    start = dm4310.joint()
    answer = dm4310.send(0x7FF, write(10, after))[0]
    assert struct.unpack("<I", bytes(answer.data[4:]))[0] == after
    dm4310.wait(1.0)
    assert dm4310.joint() == pytest.approx(start, abs=0.02)
    assert dm4310.send(*AT_REST[after])[0].data[0] >> 4 == State.ENABLED


@pytest.mark.parametrize("register, value, kind", [
    (21, float("nan"), "<f"), (21, float("inf"), "<f"), (22, -1.0, "<f"), (23, 0.0, "<f"),
    (10, 0, "<I"), (10, 5, "<I"), (3, 1.5, "<f"), (4, 0.0, "<f"), (5, 10.0, "<f"),
    (27, -1.0, "<f"), (28, float("-inf"), "<f"), (24, 50.0, "<f"), (29, 48.0, "<f"),
    (35, 12, "<I")], ids=lambda x: str(x))
def test_a_write_out_of_the_firmwares_range_is_refused_and_moves_nothing(dm4310, register,
                                                                         value, kind):
    """The firmware checks each write (write_register: PMAX/VMAX/TMAX > 0, CTRL_MODE 1-4,
    OC_Value in (0, 1), ACC > 0, DEC < 0, KP_APR/KI_APR >= 0, I_BW 100-10000, OV_Value up
    to 32 V, can_br up to 11; NaN and infinity: hil's choice) and answers with the value it
    kept."""
    dm4310.send(0x001, pack_command(MitCommand(0.5, 0.0, 20.0, 0.5, 0.0), DM4310))
    dm4310.wait(0.5)
    start = dm4310.joint()
    kept = struct.unpack(kind, bytes(dm4310.send(0x7FF, bytes([1, 0, 0x33, register, 0, 0, 0,
                                                                 0]))[0].data[4:]))[0]
    answer = dm4310.send(0x7FF, write(register, value, kind))[0]
    assert struct.unpack(kind, bytes(answer.data[4:]))[0] == kept
    dm4310.wait(0.5)
    assert dm4310.joint() == pytest.approx(start, abs=0.005)


def test_new_ranges_while_enabled_move_nothing(dm4310):
    """PMAX, VMAX and TMAX are taken while enabled, any positive value (write_register); the
    command already decoded stands: the motor holds where it was."""
    dm4310.send(0x001, pack_command(MitCommand(0.5, 0.0, 20.0, 0.5, 0.0), DM4310))
    dm4310.wait(0.5)
    start = dm4310.joint()
    for register, value in ((21, 3.0e38), (22, 1e-6), (23, 1e6)):
        answer = dm4310.send(0x7FF, write(register, value, "<f"))[0]
        assert struct.unpack("<f", bytes(answer.data[4:]))[0] == pytest.approx(value, rel=1e-6)
    dm4310.wait(0.5)
    assert dm4310.joint() == pytest.approx(start, abs=0.005)


def test_save_zero_ends_a_move_in_progress_where_it_is(dm4310):
    """FE sets the command's position to 0, the new zero (app_commands.c,
    CAN_COMMAND_SET_ZERO): a position-velocity move in progress stops here."""
    dm4310.send(0x7FF, write(10, ControlMode.POSITION_VELOCITY))
    dm4310.send(0x7FF, write(5, -20.0, "<f"))              # DEC: 20 rad/s²
    dm4310.send(0x101, struct.pack("<ff", 2.5, 2.0))
    dm4310.wait(0.3)
    start = dm4310.joint()
    assert 0.2 < start < 1.5
    dm4310.send(0x001, SAVE_ZERO)
    dm4310.wait(1.0)
    assert dm4310.joint() == pytest.approx(start, abs=2.0 ** 2 / (2 * 20))


def test_clear_error_disables_an_enabled_motor(dm4310):
    """FB clears the error and disarms the motor (app_commands.c, CAN_COMMAND_CLEAR_FAULT)."""
    assert dm4310.send(0x001, CLEAR_ERROR)[0].data[0] >> 4 == State.DISABLED


def test_a_silenced_motor_hears_no_command_of_any_mode(dm4310):
    """``hil sim --fault silence``: the drive leaves its bus, "from now on the drive sends and
    hears nothing" (DriveProfile.detach). A DM-J drive left its command handlers subscribed
    (made anew for each call, they were not the ones it had subscribed): disabled by a frame
    it should not have heard."""
    dm4310.bench.fault("yaw", "silence")
    assert dm4310.send(0x001, DISABLE) == []
    assert dm4310.send(0x201, struct.pack("<f", 5.0) + bytes(4)) == []
    assert dm4310.bench.sim.drives[0].core.power is Power.ENABLED


def test_registers_are_saved_only_while_disabled():
    """The firmware stores its registers on 0xAA only while disarmed (parameter_protocol.c)."""
    motor = lock_step_dm4310()
    motor.send(0x001, ENABLE)
    motor.send(0x7FF, write(27, 42.0, "<f"))
    motor.send(0x7FF, bytes([1, 0, 0xAA, 0, 0, 0, 0, 0]))
    assert motor.drive.saved[27] != 42.0
    motor.send(0x001, DISABLE)
    motor.send(0x7FF, bytes([1, 0, 0xAA, 0, 0, 0, 0, 0]))
    assert motor.drive.saved[27] == 42.0


# --- the TIMEOUT watchdog, lock-step ----------------------------------------------------

def lock_step_dm4310() -> LockStep:
    """Motor 1 (a DM4310, MIT mode) at rest at 0 rad, TIMEOUT 2000 x 50 us (0.1 s)."""
    core = DriveCore(DriveParameters(**{**TEST_MOTOR_DRIVE, "watchdog_timeout": 0.1}))
    core.measure(0.0, 0.0)
    return LockStep(DamiaoDrive(drive_config(1, "damiao", DamiaoOptions()), core,
                                threading.RLock()))


HOLD = pack_command(MitCommand(0.0, 0.0, 5.0, 0.3, 0.0), DM4310)


def test_re_enabling_after_a_pause_is_not_lost_communication():
    """Issue 64: enable, command, disable, 0.4 s, enable, a command every 2 ms: the motor
    reported LOST COMMUNICATION (0xD) at once, the command before the disable counting. The
    DM4310's firmware counts its communication age only while enabled and zeroes it on every
    frame for the motor (recovered in github.com/umeow0716/damiao_firmware, app/src/safety.c)."""
    motor = lock_step_dm4310()
    assert motor.states_re_enabled_after_a_pause(0x001, ENABLE, DISABLE, HOLD) == {"ENABLED"}


def test_the_enable_frame_starts_the_timeout_and_any_frame_for_the_motor_feeds_it():
    """The firmware's communication age restarts on every frame whose id addresses the motor,
    before the command's mode is looked at (github.com/umeow0716/damiao_firmware,
    app/src/safety.c, safety_note_control_frame): a velocity-mode frame to an MIT-mode motor
    moves nothing but feeds it; enabled and silent, the motor is lost after TIMEOUT."""
    motor = lock_step_dm4310()
    motor.send(0x001, ENABLE)
    motor.send(0x001, HOLD)
    for _ in range(15):
        motor.wait(0.02)
        motor.send(0x201, struct.pack("<f", 0.0) + bytes(4))       # VEL, CTRL_MODE is MIT
    assert motor.drive.state is State.ENABLED
    motor.send(0x001, CLEAR_ERROR)
    motor.send(0x001, DISABLE)
    motor.send(0x001, ENABLE)
    motor.wait(0.2)                                   # never commanded since the enable
    assert motor.drive.state is State.LOST_COMMUNICATION


def test_timeout_is_off_by_default(tmp_path):
    """Issue 64: hil's 0.1 s was tighter than published clients assume. TIMEOUT (register 9)
    ships as 0, off (the DM4310 firmware's factory configuration, recovered in
    github.com/umeow0716/damiao_firmware, app/src/app_config.c)."""
    text = CONFIG.read_text().replace("defaults: {protocol: damiao, watchdog_timeout: 0.5}",
                                      "defaults: {protocol: damiao}")
    path = tmp_path / "damiao.yaml"
    path.write_text(text.replace("robot: damiao_one_axis.urdf",
                                 f"robot: {CONFIG.parent / 'damiao_one_axis.urdf'}"))
    drive = load_bus_config(path).buses[0].drives[0]
    assert drive.watchdog_timeout == 0.0


# --- published client libraries ---------------------------------------------------------

def test_damiao_motor_drives_the_motor_through_its_readme_sequence(master):
    """python ``damiao-motor`` 1.0.6's README: a controller on the bus, add_motor, enable_all,
    ensure_control_mode("MIT"), send_cmd_mit, get_states, shutdown (its controller reads
    the bus itself, here python-can's ``virtual``)."""
    from damiao_motor import DaMiaoController

    controller = DaMiaoController(channel=master.channel, bustype=master.interface)
    try:
        motor = controller.add_motor(motor_id=0x01, feedback_id=0x11, motor_type="4310")
        controller.enable_all()
        motor.ensure_control_mode("MIT")
        deadline = time.monotonic() + 3.0
        while time.monotonic() < deadline:        # its README sends one; a loop holds it
            motor.send_cmd_mit(target_position=1.0, target_velocity=0.0, stiffness=20.0,
                               damping=0.5, feedforward_torque=0.0)
            time.sleep(0.01)
        state = motor.get_states()
        assert state["status"] == "ENABLED"
        assert state["pos"] == pytest.approx(1.0, abs=0.02)
        assert state["pos"] == pytest.approx(master.joint(), abs=2 * POSITION_LSB)
        controller.disable_all()
        time.sleep(0.1)
        assert master.drive.core.power is Power.DISABLED
    finally:
        controller.shutdown()


@pytest.mark.socketcan
def test_motorbridge_drives_the_motor_through_its_readme_sequence_over_socketcan():
    """``motorbridge`` 0.5.6 (a Rust core behind a Python SDK, SocketCAN only on Linux: run
    inside User-Mode Linux's vcan0): Controller, add_damiao_motor, enable_all, ensure_mode
    MIT, send_mit, get_state, disable_all."""
    missing = socketcan_missing()
    if missing:
        pytest.skip(missing)
    from motorbridge import Controller, Mode

    master = RealTimeMaster.of(CONFIG, vcan="vcan0")
    try:
        with Controller("vcan0") as controller:
            motor = controller.add_damiao_motor(0x01, 0x11, "4310")
            controller.enable_all()
            motor.ensure_mode(Mode.MIT, 2000)
            deadline = time.monotonic() + 3.0
            while time.monotonic() < deadline:
                motor.send_mit(-0.8, 0.0, 20.0, 0.5, 0.0)
                controller.poll_feedback_once()
                time.sleep(0.01)
            state = motor.get_state()
            assert state is not None and state.status_code == State.ENABLED
            assert state.pos == pytest.approx(-0.8, abs=0.02)
            assert state.pos == pytest.approx(master.joint(), abs=2 * POSITION_LSB)
            controller.disable_all()
            time.sleep(0.1)
            assert master.drive.core.power is Power.DISABLED
    finally:
        master.close()


# --- hil's own side: hil init with a model, hil's master ----------------------------------

def test_hil_init_with_a_model_writes_the_models_ranges_and_figures(tmp_path):
    """Issue 42: `hil init ROBOT --protocol damiao --motor DM4340` writes a config whose
    ranges are the model's (the maker's Limit_Param: 12.5 rad, 8 rad/s, 28 N·m) and whose
    drives have its torques (27 N·m peak, 9 rated)."""
    from hil.cli import main

    output = tmp_path / "one.yaml"
    assert main(["init", str(TESTS / "fixtures" / "damiao_one_axis.urdf"), "--protocol",
                 "damiao", "--motor", "DM-J4340", "-o", str(output)]) == 0
    drive = load_bus_config(output).drives[0]
    ranges = drive.options.ranges()
    assert (ranges.p_max, ranges.v_max, ranges.t_max) == (12.5, 8, 28)
    assert drive.options.model is MODELS["DM4340"]
    assert (drive.peak_torque, drive.holding_brake) == (27, False)


def test_hil_init_refuses_a_model_the_protocol_does_not_know(tmp_path, capsys):
    from hil.cli import main

    assert main(["init", str(TESTS / "fixtures" / "damiao_one_axis.urdf"), "--protocol",
                 "damiao", "--motor", "DM9999", "-o", str(tmp_path / "x.yaml")]) == 1
    assert "one of: DM3507, DM4310" in capsys.readouterr().err


def test_hils_master_drives_damiao_motors_in_mit_mode_lock_step():
    from hil.controllers import GoalStatus

    result, position = hils_master_moves(CONFIG, "yaw", 0.5)
    assert result.status is GoalStatus.SUCCEEDED, result
    assert position == pytest.approx(0.5, abs=0.01)
