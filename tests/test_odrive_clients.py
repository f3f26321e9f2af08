"""ODrive axes as firmware 0.6 ships and takes frames, driven by published clients.

Sources: ODrive's CAN protocol page (docs.odriverobotics.com, CANSimple for firmware 0.6: the
watchdog off by default, encoder estimates every 10 ms), its DBC
(odrive-cansimple-0.6.10.dbc, in the PyPI package ``odrive-can``), the open firmware's
``can_simple.cpp`` (frames decoded from their 8-byte buffer whatever their length, a Get_*
requested by an RTR or a frame of length 0, every frame feeding the watchdog) and ODrive's
CAN guide's Python example (python-can and ``struct``: a 4-byte Set_Axis_State)."""

from __future__ import annotations

import asyncio
import struct
import time

import can
import pytest

from conftest import TESTS, RealTimeMaster
from hil.bus_config import load_bus_config
from hil.can.frame import Frame
from hil.can.router import start_router
from hil.drives import Power
from hil.protocols.odrive import TURN, AxisState, Cmd, InputMode, ODriveError, can_id
from hil.realtime import LOCK_STEP
from hil.simulator import Simulator

#: judged against the host's stalls (tests/host_stalls.py): the drives run in real time beside
#: the client libraries
pytestmark = pytest.mark.real_time

CONFIG = TESTS / "fixtures" / "odrive_one_axis.yaml"


@pytest.fixture
def master(hil_drives):
    return RealTimeMaster(hil_drives(CONFIG))


def _heartbeat(master) -> tuple[int, int, int, int]:
    reply = master.ask(can_id(0, Cmd.HEARTBEAT), remote=True, answer_id=can_id(0, Cmd.HEARTBEAT))
    return struct.unpack("<IBBB", bytes(reply.data[:7]))


def test_the_makers_can_guide_example_drives_the_axis(master):
    """ODrive's CAN guide (Python): closed loop with ``struct.pack('<I', 8)`` (4 bytes), wait
    for the heartbeat to say so, a position, the cyclic encoder estimates, then IDLE."""
    node_id = 0
    bus = master.bus
    while bus.recv(timeout=0) is not None:
        pass
    bus.send(can.Message(arbitration_id=node_id << 5 | 0x07, data=struct.pack("<I", 8),
                            is_extended_id=False))
    for msg in bus:
        if msg.arbitration_id == node_id << 5 | 0x01:
            error, state, result, traj_done = struct.unpack("<IBBB", bytes(msg.data[:7]))
            if state == 8:
                break
    bus.send(can.Message(arbitration_id=node_id << 5 | 0x0C,
                            data=struct.pack("<fhh", 0.5, 0, 0), is_extended_id=False))
    time.sleep(1.0)
    estimates = []
    for msg in bus:                    # the estimates come every 10 ms without a request
        if msg.arbitration_id == node_id << 5 | 0x09:
            estimates.append(struct.unpack("<ff", bytes(msg.data)))
            if len(estimates) == 20:
                break
    position = estimates[-1][0]
    assert position == pytest.approx(0.5, abs=0.01)
    # the motor side in turns is the joint's through the 10:1 gear
    assert position * TURN / 10 == pytest.approx(master.joint(), abs=2e-3)
    bus.send(can.Message(arbitration_id=node_id << 5 | 0x07, data=struct.pack("<I", 1),
                            is_extended_id=False))
    time.sleep(0.1)
    assert master.drive.core.power is not Power.ENABLED


def test_odrive_can_drives_the_axis_through_its_readme_sequence(master):
    """``odrive-can`` 2.1 (ROX Automation): ODriveCAN on the bus, start (waits for a
    heartbeat), clear_errors, set_controller_mode, set_axis_state CLOSED_LOOP_CONTROL,
    set_input_pos, get_encoder_estimates (an RTR), stop (IDLE)."""
    from odrive_can.odrive import ODriveCAN

    async def sequence() -> dict:
        drive = ODriveCAN(axis_id=0, can_bus=master.bench.bus())
        await drive.start()
        drive.clear_errors()
        drive.set_controller_mode("POSITION_CONTROL", "PASSTHROUGH")
        await drive.set_axis_state("CLOSED_LOOP_CONTROL")
        drive.set_input_pos(-0.75)
        await asyncio.sleep(1.0)
        estimates = await drive.get_encoder_estimates()
        drive.stop()
        await asyncio.sleep(0.2)
        return estimates

    estimates = asyncio.run(sequence())
    assert estimates["Pos_Estimate"] == pytest.approx(-0.75, abs=0.01)
    assert estimates["Pos_Estimate"] * TURN / 10 == pytest.approx(master.joint(), abs=2e-3)
    assert master.drive.axis_state is AxisState.IDLE


def test_short_frames_are_decoded_from_the_8_byte_buffer_as_the_firmware_does(master):
    master.ask(can_id(0, Cmd.SET_AXIS_STATE), bytes([8]), timeout=0.2)          # one byte
    assert _heartbeat(master)[1] == AxisState.CLOSED_LOOP_CONTROL
    master.ask(can_id(0, Cmd.SET_AXIS_STATE), bytes([1]), timeout=0.2)
    assert _heartbeat(master)[1] == AxisState.IDLE


def test_a_data_frame_of_length_zero_requests_like_an_rtr(master):
    reply = master.ask(can_id(0, Cmd.GET_VERSION), b"", answer_id=can_id(0, Cmd.GET_VERSION))
    assert reply is not None and len(reply.data) == 8 and reply.data[5] == 6    # fw 0.6


def test_the_watchdog_is_off_as_the_firmware_ships_it(master):
    assert master.drive.core.parameters.watchdog_timeout == 0
    master.ask(can_id(0, Cmd.SET_AXIS_STATE), struct.pack("<I", 8), timeout=0.2)
    master.ask(can_id(0, Cmd.SET_INPUT_POS), struct.pack("<fhh", 0.0, 0, 0), timeout=0.2)
    time.sleep(0.5)                       # silence: no watchdog disarms the axis
    error, state, _, _ = _heartbeat(master)
    assert (error, state) == (ODriveError.NONE, AxisState.CLOSED_LOOP_CONTROL)


def test_a_configured_watchdog_disarms_a_silent_axis(tmp_path):
    config = tmp_path / "watched.yaml"
    config.write_text(CONFIG.read_text().replace("robot: one_axis.urdf",
                                                 f"robot: {TESTS / 'fixtures' / 'one_axis.urdf'}")
                      .replace("holding_brake: false}", "holding_brake: false, "
                               "watchdog_timeout: 0.1}"))
    master = RealTimeMaster.of(config)
    try:
        master.ask(can_id(0, Cmd.SET_AXIS_STATE), struct.pack("<I", 8), timeout=0.2)
        time.sleep(0.4)
        error, state, _, _ = _heartbeat(master)
        assert error & ODriveError.WATCHDOG_TIMER_EXPIRED and state == AxisState.IDLE
    finally:
        master.close()


def test_a_trap_traj_move_takes_the_time_its_limits_imply():
    """Issue 42: 2 turns at 1 turn/s, accelerating and decelerating at 2 turns/s²: a
    trapezoid of d/v + v/a = 2.5 s. Lock-step (a cycle is 2 ms of plant time, each one
    asked for by the encoder-estimates RTR); the trajectory is done within one cycle of it."""
    config = load_bus_config(CONFIG)
    channel = f"trap-{time.monotonic_ns()}"
    bus, master = (can.Bus(interface="virtual", channel=channel) for _ in range(2))
    sim = Simulator(config, {"axis": bus}, LOCK_STEP)
    sim.start()
    answers = []
    router = start_router(master)
    router.subscribe(can_id(0, Cmd.HEARTBEAT), lambda frame: answers.append(frame.data))
    try:
        def send(cmd, data=b"", remote=False):
            router.send(Frame(can_id(0, cmd), data, remote=remote))

        send(Cmd.SET_CONTROLLER_MODE, struct.pack("<II", 3, InputMode.TRAP_TRAJ))
        send(Cmd.SET_TRAJ_VEL_LIMIT, struct.pack("<f4x", 1.0))
        send(Cmd.SET_TRAJ_ACCEL_LIMITS, struct.pack("<ff", 2.0, 2.0))
        send(Cmd.SET_AXIS_STATE, struct.pack("<I4x", 8))
        send(Cmd.SET_INPUT_POS, struct.pack("<fhh", 2.0, 0, 0))
        cycles = 0
        while cycles < 2000:
            send(Cmd.GET_ENCODER_ESTIMATES, remote=True)      # one cycle of plant time
            cycles += 1
            answers.clear()
            send(Cmd.HEARTBEAT, remote=True)
            deadline = time.monotonic() + 2
            while not answers and time.monotonic() < deadline:
                time.sleep(0.0005)
            if answers and answers[-1][6]:                    # Trajectory_Done_Flag
                break
        period = 1 / config.cycle_hz
        assert abs(cycles * period - (2.0 / 1.0 + 1.0 / 2.0)) <= period + 1e-9, cycles
    finally:
        router.stop(1)
        sim.close()
        bus.shutdown()
        master.shutdown()


@pytest.mark.parametrize("command, data", [
    (Cmd.CLEAR_ERRORS, bytes(1)), (Cmd.ESTOP, b""),
    (Cmd.SET_ABSOLUTE_POSITION, struct.pack("<f4x", 5.0)),
    (Cmd.SET_TRAJ_VEL_LIMIT, struct.pack("<f4x", 9.0)),
    (Cmd.SET_POS_GAIN, struct.pack("<f4x", 80.0))], ids=lambda v: getattr(v, "name", ""))
def test_no_frame_but_a_setpoint_moves_an_enabled_axis(master, command, data):
    """Issue 42: a frame moves a motor only where the product moves on it. Estop disarms
    (the axis coasts, here at rest); Set_Absolute_Position moves the position scale, not the
    axis (the setpoint moves with it)."""
    master.ask(can_id(0, Cmd.SET_AXIS_STATE), struct.pack("<I", 8), timeout=0.2)
    master.ask(can_id(0, Cmd.SET_INPUT_POS), struct.pack("<fhh", 0.2, 0, 0), timeout=0.2)
    time.sleep(0.6)
    before = master.joint()
    master.ask(can_id(0, command), data, timeout=0.2)
    time.sleep(0.5)
    assert master.joint() == pytest.approx(before, abs=2e-3)
