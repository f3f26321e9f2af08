"""The simulator's time modes and process behaviour."""

from __future__ import annotations

import contextlib
import math
import os
import signal
import struct
import subprocess
import sys
import threading
import time
import uuid

import can
import numpy as np
import pytest

from conftest import ROOT, TEST_MOTOR_DRIVE, UR3_VIRTUAL, CanopenBench, free_port

from hil.bus_config import load_bus_config
from hil.can.frame import Frame
from hil.can.router import start_router
from hil.cli import common
from hil.cli.sim import status_lines
from hil.drives import DriveCore, DriveParameters, Fault
from hil.errors import BootTimeout, BringUpError
from hil.hardware import (LOCK_STEP_REPLY_TIMEOUT, MISSED_ANSWER_LIMIT, CanHardwareInterface,
                          FaultKind)
from hil.simulator import LOCK_STEP_WATCHDOG, MAX_CATCH_UP, Simulator
from hil.simulator.build import bench_plant
from hil.simulator.stepping import PlantStepping
from hil.realtime import LOCK_STEP, REAL_TIME

REDUCTIONS = (120, 120, 120, 100, 100, 100)
COUNTS = 131072


def run_lock_step(cycles: int = 120) -> tuple[np.ndarray, list[bytes]]:
    """Drive all six ur3 axes through a fixed setpoint sequence with a raw CAN master."""
    bench = CanopenBench(lock_step=True)
    reader = can.BufferedReader()
    bench.network.notifier.add_listener(reader)
    send = bench.master_bus.send
    history, replies = [], []
    try:
        send(can.Message(arbitration_id=0x000, data=[0x01, 0x00], is_extended_id=False))
        time.sleep(0.2)                          # NMT start reaches every node
        while reader.get_message(0.01) is not None:
            pass                                 # drop boot-up and heartbeat frames
        for k in range(cycles):
            controlword = (0x06, 0x07)[k] if k < 2 else 0x0F
            for node, reduction in enumerate(REDUCTIONS, start=1):
                joint = 0.3 * math.sin(2 * math.pi * 0.8 * k * 0.01 + node)
                if k < 20:
                    joint *= k / 20              # ease in from the braked start
                target = round(joint * reduction / (2 * math.pi) * COUNTS) if k >= 2 else 0
                send(can.Message(arbitration_id=0x200 + node,
                                 data=struct.pack("<Hi", controlword, target),
                                 is_extended_id=False))
            send(can.Message(arbitration_id=0x080, data=b"", is_extended_id=False))
            pending = {0x180 + n for n in range(1, 7)} | {0x280 + n for n in range(1, 7)}
            deadline = time.monotonic() + 5
            while pending and time.monotonic() < deadline:
                msg = reader.get_message(0.1)
                if msg is not None and msg.arbitration_id in pending:
                    pending.discard(msg.arbitration_id)
                    replies.append(bytes(msg.data))
            assert not pending, f"cycle {k}: no TPDO from {sorted(map(hex, pending))}"
            with bench.sim.lock:
                history.append(bench.sim.plant.data.qpos.copy())
    finally:
        bench.network.notifier.remove_listener(reader)
        bench.close()
    return np.array(history), replies


def test_lock_step_runs_are_bit_identical():
    first, first_replies = run_lock_step()
    second, second_replies = run_lock_step()
    assert np.abs(first).max() > 0.05            # the arm really moved
    assert np.array_equal(first, second)         # bit for bit
    assert sorted(first_replies) == sorted(second_replies)


def test_lock_step_advances_one_control_period_per_sync():
    bench = CanopenBench(lock_step=True)
    try:
        reader = can.BufferedReader()
        bench.network.notifier.add_listener(reader)
        bench.master_bus.send(can.Message(arbitration_id=0x000, data=[0x01, 0x00],
                                          is_extended_id=False))
        time.sleep(0.2)
        before = bench.sim.plant.time
        for sync in range(1, 6):
            bench.master_bus.send(can.Message(arbitration_id=0x080, is_extended_id=False))
            # the step, however long a loaded host takes for it (a fixed 50 ms wait missed
            # the fifth on CI, 2026-11-29); more than one period per SYNC still fails below
            deadline = time.monotonic() + 10
            while (bench.sim.plant.time - before < sync * 0.01 - 1e-9
                   and time.monotonic() < deadline):
                time.sleep(0.005)
        assert bench.sim.plant.time - before == pytest.approx(5 * 0.01)
        time.sleep(0.3)                          # no SYNC, no time
        assert bench.sim.plant.time - before == pytest.approx(5 * 0.01)
    finally:
        bench.close()


def test_hil_sim_process_starts_and_stops_cleanly_on_sigterm(tmp_path):
    port = free_port()
    process = subprocess.Popen(
        [sys.executable, "-m", "hil", "sim", str(ROOT / "bus_config" / "ur3.yaml"),
         "--listen", f"tcp/127.0.0.1:{port}", "--status-period", "0"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        banner = process.stdout.readline()
        assert "hil sim: ur3, 6 drive(s)" in banner, process.stderr.read()
        process.send_signal(signal.SIGTERM)
        out, err = process.communicate(timeout=20)
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert process.returncode == 0, err
    assert "all drives disabled" in out
    assert "Traceback" not in err


def test_a_stop_signal_stops_from_a_thread_of_its_own_not_inside_the_interrupted_wait():
    """The handler never sets an Event in the main thread, which may hold that Event's lock
    when the signal lands (a `hil sim` hung so on SIGTERM)."""
    stopped, threads = threading.Event(), []

    def stop():
        threads.append(threading.current_thread().name)
        stopped.set()

    previous = common.on_stop_signals(stop)
    try:
        os.kill(os.getpid(), signal.SIGTERM)
        assert stopped.wait(5)          # the main thread waits on the Event stop() sets
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    assert threads == ["stop-signal"]


def test_hil_sim_reports_a_bad_config_without_traceback(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(f"robot: {ROOT / 'robots/ur3_description/urdf/ur3.xacro'}\nbuses: []\n")
    result = subprocess.run([sys.executable, "-m", "hil", "sim", str(bad)],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 1
    assert "bad.yaml:2: error: 'buses' must be a non-empty list" in result.stderr
    assert "Traceback" not in result.stderr



@pytest.fixture(params=[pytest.param(False, marks=pytest.mark.real_time), True],
                ids=["real-time", "lock-step"])
def master_and_sim(request):
    """The ur3 fixture's Simulator and a CanHardwareInterface on one virtual bus, brought up;
    yields (hardware, lock_step, positions where it came up)."""
    lock_step = request.param
    reply_timeout = LOCK_STEP_REPLY_TIMEOUT if lock_step else None
    with ur3_sim_and_master(lock_step, reply_timeout) as hardware:
        yield hardware, lock_step, hardware.start().positions


@contextlib.contextmanager
def ur3_sim_and_master(lock_step: bool, reply_timeout: float | None, **options):
    """The ur3 fixture's Simulator running, and a CanHardwareInterface (not started) on one
    virtual bus with it; both stopped and closed after."""
    config = load_bus_config(UR3_VIRTUAL)
    channel = f"hil-stall-{uuid.uuid4().hex[:8]}"
    sim_bus, master_bus = (can.Bus(interface="virtual", channel=channel) for _ in range(2))
    sim = Simulator(config, {"arm": sim_bus}, LOCK_STEP if lock_step else REAL_TIME)
    sim.start()
    thread = threading.Thread(target=sim.run, daemon=True)
    thread.start()
    hardware = CanHardwareInterface(config, {"arm": master_bus}, reply_timeout=reply_timeout,
                                    **options)
    try:
        yield hardware
    finally:
        hardware.stop()
        sim.stop()
        thread.join(5)
        sim.close()
        master_bus.shutdown()
        sim_bus.shutdown()


def test_a_lock_step_bring_up_whose_cycle_outlasts_the_boot_wait_goes_on_once_all_booted():
    """In lock-step one bring-up cycle waits up to its reply timeout for answers a drive in
    pre-operational does not send, longer than ``hil up``'s 3 s boot wait on a loaded host:
    every drive booted within it is no failure (local CI, 2026-11-29: "error: : not heard
    within 3 s after reset", naming no drive, for romeo's 33). A boot wait of 0 s here; the
    drives' boot-ups need only arrive within the first cycle's 5 s."""
    with ur3_sim_and_master(True, 5.0, boot_timeout=0.0) as hardware:
        assert len(hardware.start().positions) == 6


def test_drives_not_heard_within_the_boot_timeout_are_a_boot_timeout_naming_them():
    """hil.errors: a master whose drives are not heard after their reset (no sim on the bus)
    raises BootTimeout, a BringUpError and a TimeoutError, with the drives, their bus and the
    timeout, and the message it always gave."""
    config = load_bus_config(UR3_VIRTUAL)
    bus = can.Bus(interface="virtual", channel=f"hil-boot-{uuid.uuid4().hex[:8]}")
    hardware = CanHardwareInterface(config, {"arm": bus}, boot_timeout=0.0)
    try:
        with pytest.raises(BootTimeout) as raised:
            hardware.start()
    finally:
        hardware.stop()
        bus.shutdown()
    assert isinstance(raised.value, BringUpError) and isinstance(raised.value, TimeoutError)
    assert raised.value.drives == tuple(axis.label for axis in hardware.axes)
    assert (raised.value.bus, raised.value.node, raised.value.timeout) == ("arm", None, 0.0)
    assert str(raised.value).startswith(
        "error: drive node 1 (joint1) on bus 'arm'; drive node 2 ")
    assert ": not heard within 0 s after reset" in str(raised.value)


def test_a_lock_step_master_waits_for_a_bring_up_answer_as_long_as_a_drive_may_be_silent():
    """In lock-step a stalled sim is slow, not dead: a bring-up request waits as long as the
    cycles let a drive go unheard (MISSED_ANSWER_LIMIT answers of LOCK_STEP_REPLY_TIMEOUT);
    in real time that is shorter than canopen's own 0.3 s, which stands (the axis' max)."""
    config = load_bus_config(UR3_VIRTUAL)
    lock_step = CanHardwareInterface(config, {}, reply_timeout=LOCK_STEP_REPLY_TIMEOUT)
    assert lock_step.answer_silence_limit == MISSED_ANSWER_LIMIT * LOCK_STEP_REPLY_TIMEOUT
    assert CanHardwareInterface(config, {}).answer_silence_limit < 0.3


@pytest.mark.parametrize("request_timeout, waits", [(1 / 500, 0.3), (0.6, 0.6)],
                         ids=["canopen's", "longer"])
def test_a_bring_up_waits_its_request_timeout_for_each_sdo_answer(request_timeout, waits):
    """canopen's SDO client gives up on an answer after 0.3 s; a sim stalled in User-Mode
    Linux answers later than that (CI, 2026-11-28: `hil up --lock-step` failed its bring-up).
    A master that waits longer (lock-step's) holds its axes' SDO to its wait; in real time
    canopen's 0.3 s stand. A drive that never answers still fails, naming it (at the earliest
    after that wait: only a lower bound of time is judged)."""
    from hil.errors import HilError
    from hil.protocols.cia402.axis import Cia402Axis
    config = load_bus_config(UR3_VIRTUAL)
    bus = can.Bus(interface="virtual", channel=f"hil-sdo-{uuid.uuid4().hex[:8]}")
    router = start_router(bus)
    axis = Cia402Axis(config.drives[0], "arm")
    axis.attach(router)
    axis.request_timeout = request_timeout
    try:
        began = time.monotonic()
        with pytest.raises(HilError, match=r"drive node 1 \(joint1\) on bus 'arm' does not "
                                           r"answer SDO"):
            axis.configure()
        assert time.monotonic() - began >= waits
        assert axis.node.sdo.RESPONSE_TIMEOUT == waits
    finally:
        router.stop(1)
        bus.shutdown()


def test_a_controller_stall_past_the_watchdog_faults_in_real_time_only(master_and_sim):
    """Under a loaded machine (User-Mode Linux on CI) a process stalls for several 100 ms.
    In real time the drives quick-stop by their watchdog and the master reports it, even
    though its next ENABLE re-enables them at once (CiA 402 transition 16); in lock-step
    nothing moves meanwhile, so neither side may fault for it."""
    hardware, lock_step, hold = master_and_sim
    drive = hardware.config.drives[0]
    stall = 4 * max(drive.watchdog_timeout, 3 * drive.heartbeat_period)
    assert stall < LOCK_STEP_WATCHDOG
    for _ in range(10):
        hardware.cycle(hold, np.zeros_like(hold))
    time.sleep(stall)                        # the controller stalls
    faults = []
    for _ in range(10):
        hardware.cycle(hold, np.zeros_like(hold))
        faults += hardware.faults()
    if lock_step:
        assert faults == []
        assert all(axis.enabled for axis in hardware.axes)
    else:
        first = next(f for f in faults if f.node_id == 1)
        assert (first.kind, first.code) == (FaultKind.REPORTED, 0x8250)
        assert str(first) == ("drive node 1 (joint1) on bus 'arm' reported EMCY 0x8250 "
                              "RPDO timeout (setpoints stopped arriving)")


# --- real time: the plant's present ---------------------------------------------------------

@pytest.fixture
def real_time_sim():
    """The ur3 fixture's Simulator in real time on a virtual bus, not running yet, with a
    wall clock the test moves (``sim.wall_clock = fake``)."""
    channel = f"hil-present-{uuid.uuid4().hex[:8]}"
    bus = can.Bus(interface="virtual", channel=channel)
    sim = Simulator(load_bus_config(UR3_VIRTUAL), {"arm": bus})
    wall = [0.0]
    sim.wall_clock = lambda: wall[0]
    try:
        yield sim, wall
    finally:
        sim.stop()
        sim.close()
        bus.shutdown()


def start_clock(sim: Simulator) -> threading.Thread:
    """run() in a thread, until it has taken its epoch from the (fake) wall clock."""
    thread = threading.Thread(target=sim.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 5
    while sim._clock is None:
        assert time.monotonic() < deadline, "run() did not start"
        time.sleep(0.001)
    return thread


def test_touching_a_real_time_plant_brings_it_to_the_present(real_time_sim):
    sim, wall = real_time_sim
    dt = sim.plant.timestep
    thread = start_clock(sim)
    before = sim.plant.time
    wall[0] += 37.5 * dt                 # the wall clock moves on
    assert sim.now() == pytest.approx(before + 37 * dt)    # whole steps up to now
    with sim.lock:
        with sim.lock:                   # nested: no second advance inside a frame's work
            wall[0] += 5 * dt
            assert sim.plant.time == pytest.approx(before + 37 * dt)
    assert sim.now() == pytest.approx(before + 42 * dt)
    sim.stop()
    thread.join(5)


def test_a_real_time_plant_skips_a_stall_instead_of_replaying_it(real_time_sim):
    sim, wall = real_time_sim
    dt = sim.plant.timestep
    thread = start_clock(sim)
    before = sim.plant.time
    wall[0] += 3 * MAX_CATCH_UP          # the process stalled
    assert sim.now() == pytest.approx(before + dt)     # one step, and counted
    assert sim.overruns == 1
    wall[0] += 2 * dt
    assert sim.now() == pytest.approx(before + 3 * dt)  # then in step with the wall again
    sim.stop()
    thread.join(5)


def test_a_real_time_run_for_a_duration_steps_exactly_that_much_plant_time():
    channel = f"hil-duration-{uuid.uuid4().hex[:8]}"
    bus = can.Bus(interface="virtual", channel=channel)
    sim = Simulator(load_bus_config(UR3_VIRTUAL), {"arm": bus})
    try:
        sim.run(0.2)
        assert sim.plant.time == pytest.approx(0.2)
    finally:
        sim.close()
        bus.shutdown()


def test_a_frame_the_bus_will_not_send_is_lost_and_counted_and_the_plant_runs_on(real_time_sim):
    sim, wall = real_time_sim
    dt = sim.plant.timestep
    sim.start()
    runtime, = sim.buses
    send = runtime.bus.send

    def full_transmit_queue(msg, timeout=None):      # refuses node 1's EMCY only
        if msg.arbitration_id == 0x081:
            raise can.CanOperationError("Transmit buffer full")
        send(msg, timeout)

    runtime.bus.send = full_transmit_queue
    thread = start_clock(sim)
    before = sim.plant.time
    sim.raise_fault("arm", 1)                        # its EMCY cannot go out
    wall[0] += 10 * dt
    assert sim.now() == pytest.approx(before + 10 * dt)
    assert runtime.router.lost_frames == 1
    assert sim.drive("arm", 1).core.fault is Fault.FOLLOWING_ERROR
    assert any("lost 1 frame(s)" in line for line in status_lines(sim))
    sim.stop()
    thread.join(5)


def test_a_real_time_bus_answers_the_commands_of_one_delivery_in_one_send(real_time_sim):
    # a master's cycle that arrives in one delivery (a Zenoh message, handled inside one
    # entry of the lock) is answered in one send of the bus' replies, as in lock-step; a
    # SYNC that reaches the drives outside such an entry, each drive's reply on its own
    sim, _ = real_time_sim
    sim.start()
    runtime, = sim.buses
    router = runtime.router
    router.on_frames([Frame(0x000, bytes([0x01, 0x00]))])        # NMT start: PDOs on
    sends: list[list[Frame]] = []
    send_frames = router.send_frames
    router.send_frames = lambda frames: (sends.append(list(frames)), send_frames(frames))
    with sim.lock:
        router.on_frames([Frame(0x080)])                          # SYNC
        assert sends == []                                        # held while inside
    tpdos = {0x180 + node for node in range(1, 7)} | {0x280 + node for node in range(1, 7)}
    assert len(sends) == 1 and {frame.identifier for frame in sends[0]} == tpdos
    sends.clear()
    router.on_frames([Frame(0x080)])
    assert len(sends) == 6 and {frame.identifier for s in sends for frame in s} == tpdos


class EventsOnlyDrive:
    """A drive whose after_update reacts to its core's faults only (the MIT family's,
    Damiao's, ...): records each call with the faults it found."""

    follows_every_step = False

    def __init__(self):
        self.core = DriveCore(DriveParameters(**TEST_MOTOR_DRIVE))
        self.calls: list[list[Fault]] = []

    def after_update(self) -> None:
        events, self.core.events = self.core.events, []
        self.calls.append(events)


def test_a_drive_that_follows_its_faults_only_is_told_after_the_step_that_leaves_one():
    stepping = PlantStepping(bench_plant(load_bus_config(UR3_VIRTUAL)))
    drive = EventsOnlyDrive()
    stepping.add(drive, 0)
    stepping.step()
    assert drive.calls == []                  # no fault: not called
    drive.core.enable()
    drive.core.raise_fault(Fault.EMERGENCY_STOP)
    stepping.step()
    stepping.step()
    assert drive.calls == [[Fault.EMERGENCY_STOP]]      # once, after the next step


def test_the_heartbeats_of_one_watchdog_check_go_out_in_one_zenoh_message(endpoint):
    # every drive's heartbeat falls due at start: a check sends all six, as one message
    # (one put each was a message, and a wake-up of the master's receiving thread, a beat)
    bus = can.Bus(interface="zenoh", channel=f"test/{uuid.uuid4().hex[:8]}/arm",
                  listen=[endpoint])
    sim = Simulator(load_bus_config(UR3_VIRTUAL), {"arm": bus}, LOCK_STEP)
    try:
        sim.start()
        frames, messages = bus.counters.sent, bus.counters.messages_sent
        sim._check_watchdogs()
        assert (bus.counters.sent - frames, bus.counters.messages_sent - messages) == (6, 1)
    finally:
        sim.close()
        bus.shutdown()
