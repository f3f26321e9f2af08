"""`hil viz` and `hil up` as processes: what they record, and how they end."""

from __future__ import annotations

import argparse
import collections
import contextlib
import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
import urllib.request

import can
import numpy as np
import pytest
import rerun.chunk

from hil.bus_config import load_bus_config
from hil.cli import up
from hil.cli.run_progress import Progress
from hil.cli.up.children import make_children
from hil.cli.up.robots import RobotRun
from hil.supervisor import RECORDER_STOP_TIMEOUT, STOP_TIMEOUT
from hil.messaging.zenoh_api import RunSubscriber
from hil.zenoh_session import ZenohSettings, close, session
from conftest import ROOT, free_port, read_rrd, rrd_series, rrd_verify_errors

#: judged against the host's stalls (tests/host_stalls.py): `hil up` and its processes run in
#: real time (the demos at their pace)
pytestmark = pytest.mark.real_time

PIGOT_CONFIG = str(ROOT / "bus_config" / "pigot.yaml")
#: the entity with a row for every cycle recorded (hil.visualisation.recorder)
AXIS_ENTITY = "/cycle"
#: a visualiser whose recording is the point, not its scheduling: under SCHED_IDLE (its
#: default in real time) the other tests' load on 2 CI vCPUs starved one for minutes, its
#: start-up and its stop alike (reproduced beside two busy loops)
KEEPING_UP = ("--normal-scheduling",)


def hil(*args, **kwargs) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "hil", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, **kwargs)


def killed_temp(tmp_path) -> dict[str, str]:
    """The environment of a process the test kills with SIGKILL: its temporary folder (hil
    viz's copy of the description) inside the test's, as nothing cleans up after SIGKILL."""
    (tmp_path / "tmp").mkdir(exist_ok=True)
    return {**os.environ, "TMPDIR": str(tmp_path / "tmp")}


def gone(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    with open(f"/proc/{pid}/stat") as stat:       # a zombie has ended too
        return stat.read().split(")")[-1].split()[0] == "Z"


def wait_for_cycles(published: list, count: int, timeout: float = 60) -> None:
    """Until ``count`` more cycles were published than had been at the call (``published``: a
    RunSubscriber's batches): the host's pace, not a fixed sleep, says when enough is recorded.
    Counting from the call, not from the listener's start, keeps a slow start of the process
    under test (seconds on a loaded host) from eating the cycles it is meant to record."""
    deadline = time.monotonic() + timeout
    target = count + sum(len(b) for b in published)
    while sum(len(b) for b in published) < target:
        assert time.monotonic() < deadline, f"{count} cycles not published in {timeout} s"
        time.sleep(0.1)


@contextlib.contextmanager
def published_cycles(endpoint: str):
    """The batches the pigot's controller at ``endpoint`` publishes, heard until the block
    ends (a list, for :func:`wait_for_cycles`)."""
    published: list = []
    listener = RunSubscriber(session(ZenohSettings(connect=(endpoint,))), "pigot",
                             published.append, lambda *_: None, pytest.fail)
    try:
        yield published
    finally:
        listener.close()


def test_viz_records_every_published_cycle_of_the_controller(tmp_path, processes):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    control = hil("control", PIGOT_CONFIG, "--fake", "--listen", endpoint)
    processes.append(control)
    assert "hil control:" in control.stdout.readline()
    with published_cycles(endpoint) as published:
        viz = hil("viz", PIGOT_CONFIG, "--no-can", "--connect", endpoint, *KEEPING_UP,
                  "--save", str(tmp_path / "run.rrd"))
        processes.append(viz)
        assert "hil viz:" in viz.stdout.readline()
        wait_for_cycles(published, 1500)         # from the viz's start: 3 s of a quiet host
        control.send_signal(signal.SIGTERM)      # its last batch goes out as it stops
        control.communicate(timeout=20)
        time.sleep(0.5)
        viz.send_signal(signal.SIGTERM)
        out, err = viz.communicate(timeout=30)
    assert viz.returncode == 0, err
    # the viz may have joined after the first batches: compare from its first one on
    rows, _ = read_rrd(tmp_path / "run.rrd")
    logged = rows[AXIS_ENTITY]
    summary = re.search(r"(\d+) cycles in (\d+) batches, (\d+) lost", out)
    assert summary, out
    assert int(summary.group(1)) == logged and int(summary.group(3)) == 0
    tail = sum(len(b) for b in published[-int(summary.group(2)):])
    assert logged == tail and logged > 500, (logged, tail)


def test_a_recording_cut_off_by_sigkill_reads_back_up_to_its_last_flush(tmp_path, processes):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    control = hil("control", PIGOT_CONFIG, "--fake", "--listen", endpoint)
    processes.append(control)
    assert "hil control:" in control.stdout.readline()
    save = tmp_path / "cut.rrd"
    viz = hil("viz", PIGOT_CONFIG, "--no-can", "--connect", endpoint, *KEEPING_UP,
              "--save", str(save), env=killed_temp(tmp_path))
    processes.append(viz)
    assert "hil viz:" in viz.stdout.readline()
    with published_cycles(endpoint) as published:
        wait_for_cycles(published, 2000)         # 500 Hz: 4 s, several flushes
    viz.kill()
    viz.wait(timeout=20)
    # no footer (it never closed): rerun scans the stream, as its viewer does
    cycles = []
    for chunk in rerun.chunk.RrdReader(save).stream():
        if chunk.entity_path == AXIS_ENTITY and not chunk.is_static:
            cycles.append(chunk.num_rows)
    assert sum(cycles) > 500, cycles


@pytest.mark.slow
def test_up_runs_the_demo_and_records_axes_robot_and_can_traffic(tmp_path):
    save = tmp_path / "out" / "run.rrd"
    result = subprocess.run([sys.executable, "-m", "hil", "up", "pigot", "--demo", "--lock-step",
                             "--no-viewer", "--save", str(save)], capture_output=True,
                            text=True, timeout=300, cwd=tmp_path)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "demo succeeded" in result.stdout
    assert rrd_verify_errors(save) == ""               # rerun's own schema check
    rows, static = read_rrd(save)
    assert rows[AXIS_ENTITY] > 1000 and rows["/joints"] > 10 * 8    # 8 joints, the mimic too
    # the bus loads per second of bus time: a lock-step run's as `hil check` estimates them
    # (worst-case stuffing: each bus' second column; the third draws the estimate)
    _, loads = rrd_series(save, "/bus/load")
    config = load_bus_config(ROOT / "bus_config" / "pigot.yaml")
    for k, bus in enumerate(config.buses):
        estimate = 100 * bus.load().worst_ratio
        cycling = loads[:, 3 * k + 1][loads[:, 3 * k + 1] > estimate / 2]
        # rows on bus time, each frame counted by its sender's stamp (hil.can.monitor); the
        # first and the last row straddle the cycles' start and end: the median row is the
        # bus' load (counted as frames reached the visualiser, CI's loaded host once made
        # rows of 48-134 % where the load was 91 %)
        assert len(cycling) >= 1, (bus.name, loads[:, 3 * k + 1])
        assert np.median(cycling) == pytest.approx(estimate, rel=0.05), (bus.name, cycling)
        assert loads[:, 3 * k + 2] == pytest.approx(100 * bus.load().worst_ratio, rel=1e-6)
    assert rows["/bus/load"] > 0 and rows["/drives/limits"] > 0
    assert rows["/drives/finger_pri_1_motor/state"] >= 1
    assert any(p.startswith("/robot/pigot/visual_geometries/arm_link_6") for p in static)
    # the CAN log is BLF, its channels numbered in the config's order of the buses
    frames = collections.Counter(
        (m.channel, m.arbitration_id) for m in can.LogReader(save.with_name("run.can.blf")))
    for node in range(1, 8):                 # every drive's TPDO1 and every RPDO
        number = 1 if node <= 3 else 2
        assert frames[(number, 0x180 + node)] > 1000 and frames[(number, 0x200 + node)] > 1000
    # the CAN log says what it missed: the frames the monitor received are in it, less the
    # ones its FIFO could not hold and those still arriving as it closed (the controller is
    # stopped by then: a few heartbeats), and the frames lost on the way are counted
    for number, bus in enumerate(("arm", "wrist"), start=1):
        found = re.search(rf"hil up: CAN log, bus {bus} \(log channel {number}\): sent 0 in 0 "
                          r"messages, received (\d+) in \d+, lost on the way (\d+), overrun "
                          r"(\d+)", result.stdout)
        assert found, result.stdout
        received, _, overrun = map(int, found.groups())
        logged = sum(n for (channel, _), n in frames.items() if channel == number)
        assert 0 <= received - overrun - logged <= 50, (bus, received, overrun, logged)
    assert "hil up: CAN log (Vector BLF): " in result.stdout
    logs = save.with_name("run.logs")
    assert {p.name for p in logs.iterdir()} == {"sim.log", "control.log", "viz.log"}


def start_up(tmp_path, processes, drain: bool = True
             ) -> tuple[subprocess.Popen, dict[str, int], list[str]]:
    """`hil up` (no demo) until all three children are ready; their pids by name; the rest
    of its output read on into the lines (``drain``) or left to the caller."""
    up = hil("up", "pigot", "--lock-step", "--no-viewer", "--save", str(tmp_path / "run.rrd"),
             cwd=tmp_path)
    processes.append(up)
    pids, lines = {}, []
    while len(pids) < 3:
        line = up.stdout.readline()
        assert line, "hil up ended early: " + "".join(lines) + up.stderr.read()
        lines.append(line)
        ready = re.search(r"hil up: (\w+) ready \(pid (\d+)\)", line)
        if ready:
            pids[ready.group(1)] = int(ready.group(2))
    if drain:
        threading.Thread(target=lambda: lines.extend(up.stdout), daemon=True).start()
    return up, pids, lines


@pytest.mark.parametrize("victim", ["sim", "control"])
def test_up_with_a_killed_child_ends_nonzero_naming_it_and_leaves_no_process(
        victim, tmp_path, processes):
    up, pids, _ = start_up(tmp_path, processes)
    os.kill(pids[victim], signal.SIGKILL)
    # hil up's own bound: each child SIGTERMed, then killed past its stop timeout (control
    # and sim 15 s, the recording visualiser 60 s); a CI run's took more than 60 s in all
    up.wait(timeout=STOP_TIMEOUT * 2 + RECORDER_STOP_TIMEOUT + 30)
    err = up.stderr.read()
    assert up.returncode == 1
    assert f"{victim} (pid {pids[victim]}) exited with status -9" in err
    assert "its last lines" in err
    for name, pid in pids.items():
        assert gone(pid), f"{name} (pid {pid}) is still running"


def test_up_stops_every_child_cleanly_on_ctrl_c(tmp_path, processes):
    up, pids, lines = start_up(tmp_path, processes)
    up.send_signal(signal.SIGINT)
    up.wait(timeout=60)
    assert up.returncode == 130, up.stderr.read()
    for name, pid in pids.items():
        assert gone(pid), f"{name} (pid {pid}) is still running"
    control_log = (tmp_path / "run.logs" / "control.log").read_text()
    assert "stopped; drives disabled" in control_log
    assert (tmp_path / "run.rrd").stat().st_size > 0


def test_up_whose_reader_leaves_stops_every_child_and_ends_as_a_filter_does(
        tmp_path, processes):
    """`hil up | head`, or a harness that died: the reader of its output leaves. It stops
    as on SIGTERM, exit status 141 (128 + SIGPIPE); it used to leave sim and control running
    and wait at exit for good."""
    up, pids, _ = start_up(tmp_path, processes, drain=False)
    up.stdout.close()                         # its next line meets no reader
    up.wait(timeout=60)
    assert up.returncode == 141, up.stderr.read()
    for name, pid in pids.items():
        assert gone(pid), f"{name} (pid {pid}) is still running"
    assert "stopped; drives disabled" in (tmp_path / "run.logs" / "control.log").read_text()
    assert "Traceback" not in up.stderr.read()


def test_killed_up_takes_its_children_with_it(tmp_path, processes):
    up, pids, _ = start_up(tmp_path, processes)
    up.kill()                                 # no chance to clean up: the children notice
    up.wait()
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline and not all(gone(pid) for pid in pids.values()):
        time.sleep(0.2)
    for name, pid in pids.items():
        assert gone(pid), f"{name} (pid {pid}) outlived hil up"
    assert "stopped; drives disabled" in (tmp_path / "run.logs" / "control.log").read_text()


@pytest.mark.slow
def test_up_prints_a_fault_nobody_injected_as_it_happens_and_ends_nonzero(tmp_path, processes):
    """Someone else on the bus stops drive 2 (NMT stop): its answers end, the controller
    reports it silent, ``hil up`` says so and fails, and the recording has the report."""
    up = hil("up", "pigot", "--lock-step", "--no-viewer", "--duration", "20", "--save",
             str(tmp_path / "run.rrd"), cwd=tmp_path)
    processes.append(up)
    first = up.stdout.readline()
    endpoint = re.search(r"Zenoh (tcp/\S+);", first)
    assert endpoint, first + up.stderr.read()
    for line in up.stdout:
        if "control ready" in line:
            break
    connect = (endpoint.group(1),)
    bus = can.Bus(interface="zenoh", channel="pigot/arm", connect=connect)  # linked to the sim
    try:
        for _ in range(3):          # idempotent; sent a few times so that none is left in
            bus.send(can.Message(arbitration_id=0x000, data=[0x02, 2], is_extended_id=False))
            time.sleep(0.2)         # Zenoh's batch when the session closes
    finally:
        bus.shutdown()
        close(ZenohSettings(connect=connect))
    out, err = up.communicate(timeout=120)
    assert up.returncode == 1, out + err
    assert re.search(r"hil up: control: ERROR: drive node 2 \(arm_rot_2\) on bus 'arm' is "
                     r"silent", err), err
    assert "the controller reported 1 fault(s)" in err
    rows, _ = read_rrd(tmp_path / "run.rrd")
    assert rows["/diagnostics"] == 1
    # the others ran on at speed once drive 2 was known silent (each cycle would otherwise
    # wait the whole 2 s lock-step reply timeout for it)
    assert rows[AXIS_ENTITY] > 1000


@pytest.mark.slow
def test_up_runs_two_robots_demos_together_into_one_recording(tmp_path):
    save = tmp_path / "run.rrd"
    result = subprocess.run([sys.executable, "-m", "hil", "up", "ur3", "pigot", "--demo",
                             "--lock-step", "--no-viewer", "--save", str(save)],
                            capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "hil up: ur3: demo succeeded" in result.stdout
    assert "hil up: pigot: demo succeeded" in result.stdout
    assert rrd_verify_errors(save) == ""               # the ur3's and the pigot's, lock-step
    rows, static = read_rrd(save)
    # both robots' timelines, each under its name, through both demos (ur3 6 s, pigot 4.5 s)
    for robot, cycles in (("ur3", 3000), ("pigot", 2250)):
        assert rows[f"/{robot}/cycle"] >= cycles, robot
        assert rows[f"/{robot}/joints"] > 10, robot
        assert rows[f"/{robot}/bus/load"] > 0, robot
        assert f"/{robot}/tf_static" in static
    assert not any(path.startswith(("/cycle", "/robot/")) for path in [*rows, *static])
    channels = collections.Counter(m.channel for m in can.LogReader(
        save.with_name("run.can.blf")))
    for number, bus in enumerate(("ur3/arm", "ur3/wrist", "pigot/arm", "pigot/wrist"), 1):
        assert channels[number] > 1000, channels          # numbered robot by robot, bus by bus
        assert f"hil up: CAN log, bus {bus} (log channel {number}): sent" in result.stdout
    assert {p.name for p in save.with_name("run.logs").iterdir()} == {
        "ur3.sim.log", "ur3.control.log", "pigot.sim.log", "pigot.control.log", "viz.log"}
    for robot in ("ur3", "pigot"):
        assert "stopped; drives disabled" in (
            save.with_name("run.logs") / f"{robot}.control.log").read_text()


def test_a_held_controller_brings_its_drives_up_only_once_told_on_its_input(
        watched_robot, processes):
    """hil up starts several robots' controllers held (--hold) and releases them together
    (by closing their input; a line does it too): held, a controller says so and runs no
    cycle."""
    endpoint, watch = watched_robot
    control = hil("control", "ur3", "--fake", "--hold", "--connect", endpoint,
                  stdin=subprocess.PIPE)
    processes.append(control)
    assert watch.wait_alive("control/held", 30), control.stderr.read()
    assert not watch.wait_alive("control", 1.0), "a held controller cycled"
    control.stdin.write("\n")
    control.stdin.flush()
    assert watch.wait_alive("control", 30)
    control.send_signal(signal.SIGINT)
    out, err = control.communicate(timeout=30)
    assert control.returncode == 0, out + err
    assert "stopped; drives disabled" in out


def test_a_held_controller_told_to_stop_ends_without_bringing_anything_up(
        watched_robot, processes):
    endpoint, watch = watched_robot
    control = hil("control", "ur3", "--fake", "--hold", "--connect", endpoint,
                  stdin=subprocess.PIPE)
    processes.append(control)
    assert watch.wait_alive("control/held", 30), control.stderr.read()
    control.send_signal(signal.SIGTERM)
    out, err = control.communicate(timeout=30)
    assert control.returncode == 0, out + err
    assert "0 cycles" in out or "no cycle" in out, out
    assert not watch.wait_alive("control", 0.5)


def test_up_holds_every_controller_until_all_have_started(tmp_path):
    parser = argparse.ArgumentParser()
    up.add_arguments(parser)
    robots = [RobotRun(ROOT / "bus_config" / f"{name}.yaml", load_bus_config(
        ROOT / "bus_config" / f"{name}.yaml"), Progress()) for name in ("ur3", "pigot")]
    make_children(parser.parse_args(["ur3", "pigot"]), robots, [], tmp_path,
                  tmp_path / "run.can.log")
    for robot in robots:
        control = robot.children["control"]
        assert control.held and "--hold" in control.argv
        assert not robot.children["sim"].held


def test_up_puts_each_of_several_robots_in_a_ros_namespace_of_its_own(tmp_path):
    parser = argparse.ArgumentParser()
    up.add_arguments(parser)
    args = parser.parse_args(["ur3", "pigot", "--ros", "--ros-namespace", "/lab"])
    robots = [RobotRun(ROOT / "bus_config" / f"{name}.yaml", load_bus_config(
        ROOT / "bus_config" / f"{name}.yaml"), Progress()) for name in ("ur3", "pigot")]
    make_children(args, robots, [], tmp_path, tmp_path / "run.can.log")
    for robot in robots:
        for child in robot.children.values():
            assert f"--ros-namespace=/lab/{robot.name}" in child.argv, child.argv
            assert sum(a.startswith("--ros-namespace") for a in child.argv) == 1


def test_up_refuses_two_configs_of_one_robot_before_starting_anything(tmp_path):
    result = subprocess.run([sys.executable, "-m", "hil", "up", "ur3", "ur3"],
                            capture_output=True, text=True, timeout=60, cwd=tmp_path)
    assert result.returncode == 1
    assert "robot 'ur3' is named by two configs" in result.stderr
    assert "Traceback" not in result.stderr and not (tmp_path / "run.logs").exists()


def test_up_with_a_bad_config_says_so_and_starts_nothing(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("robot: nowhere.xacro\nbuses: []\n")
    result = subprocess.run([sys.executable, "-m", "hil", "up", str(bad)], capture_output=True,
                            text=True, timeout=60, cwd=tmp_path)
    assert result.returncode == 1
    assert "bad.yaml" in result.stderr and "Traceback" not in result.stderr
    assert not (tmp_path / "run.logs").exists()


@pytest.mark.socketcan
def test_up_on_socketcan_runs_the_stack_and_logs_the_vcan_frames(tmp_path):
    """`hil up` on two vcan channels, lock-step for 5 s of wall time: every recorded cycle
    in the recording and each cycle's frames on both channels of the candump log. (Its demo
    took 92 s inside User-Mode Linux, 40 cycles a second, a third of CI's SocketCAN run;
    a trajectory over SocketCAN is test_control_stack.py's.)"""
    from conftest import socketcan_missing
    missing = socketcan_missing()
    if missing:
        pytest.skip(missing)
    save = tmp_path / "run.rrd"
    candump = tmp_path / "frames.log"            # candump's text keeps the channels' names
    result = subprocess.run([sys.executable, "-m", "hil", "up", "pigot", "--duration", "5s",
                             "--lock-step", "--can", "vcan0", "--can", "vcan1", "--no-viewer",
                             "--save", str(save), "--can-log", str(candump)],
                            capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert result.returncode == 0, result.stdout + result.stderr
    cycles = int(re.search(r"recorded (\d+) cycles", result.stdout)[1])
    rows, _ = read_rrd(save)
    assert cycles > 0 and rows[AXIS_ENTITY] == cycles, (cycles, rows[AXIS_ENTITY])
    # every cycle puts frames on both buses (SYNC and the RPDOs, the TPDOs back)
    channels = collections.Counter(m.channel for m in can.LogReader(candump))
    assert min(channels["vcan0"], channels["vcan1"]) > cycles, (channels, cycles)


def test_a_recording_in_segments_loses_at_most_its_last_to_a_sigkill(tmp_path, processes):
    """Segments of a second: killed mid-run, every closed segment opens alone (its robot
    model and series styles logged again at its start) with its cycles, and the open one up
    to its last flush; hil review finds them all."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    control = hil("control", PIGOT_CONFIG, "--fake", "--listen", endpoint)
    processes.append(control)
    assert "hil control:" in control.stdout.readline()
    save = tmp_path / "long.rrd"
    viz = hil("viz", PIGOT_CONFIG, "--no-can", "--connect", endpoint, *KEEPING_UP,
              "--save", str(save), "--segment", "1s", env=killed_temp(tmp_path))
    processes.append(viz)
    assert "long-0001.rrd and on, segments of 1 s" in viz.stdout.readline()
    with published_cycles(endpoint) as published:
        started = time.monotonic()
        wait_for_cycles(published, 2000)         # the host's pace: 4 s of a quiet one
        time.sleep(max(0.0, 4.5 - (time.monotonic() - started)))     # and four segments' time
    viz.kill()
    viz.wait(timeout=20)
    segments = sorted(tmp_path.glob("long-*.rrd"))
    assert [path.name for path in segments[:4]] == [f"long-000{n}.rrd" for n in range(1, 5)]
    assert not save.exists()
    for path in segments[:-1]:                         # closed: each passes rerun's check
        assert rrd_verify_errors(path) == "", path
    for path in segments:
        rows, static = read_rrd(path, whole=path != segments[-1])
        assert any(entity.startswith("/robot/pigot/visual_geometries") for entity in static), path
        assert rows[AXIS_ENTITY] > 0 or path == segments[-1], (path, rows)
    assert sum(read_rrd(path, whole=False)[0][AXIS_ENTITY] for path in segments) > 1500
    reviewed = subprocess.run([sys.executable, "-m", "hil", "review", str(save), "--no-viewer"],
                              capture_output=True, text=True, timeout=120)
    assert reviewed.returncode == 0, reviewed.stdout + reviewed.stderr
    assert f"{len(segments)} file(s)" in reviewed.stdout


def test_review_lists_a_runs_faults_with_their_times(tmp_path):
    """A lock-step demo with a drive fault injected: hil review names the fault, when, and
    in which file, without opening a viewer."""
    save = tmp_path / "run.rrd"
    result = subprocess.run([sys.executable, "-m", "hil", "up", "pigot", "--demo", "--lock-step",
                             "--no-viewer", "--save", str(save), "--fault", "fault:arm/2@3"],
                            capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert result.returncode == 1, result.stdout + result.stderr
    assert "review with: " in result.stdout and f"review {save}" in result.stdout
    reviewed = subprocess.run([sys.executable, "-m", "hil", "review", str(save), "--no-viewer"],
                              capture_output=True, text=True, timeout=120)
    assert reviewed.returncode == 0, reviewed.stdout + reviewed.stderr
    assert "1 fault(s)" in reviewed.stdout
    (line,) = [line for line in reviewed.stdout.splitlines() if "ERROR" in line]
    assert "drive node 2 (arm_rot_2) on bus 'arm' is in FAULT" in line
    assert re.search(r"\d{4}-\d\d-\d\d \d\d:\d\d:\d\d\.\d+, control \d+\.\d+ s", line)
    assert "[run.rrd]" in line
    assert re.search(r"cycles over \d+\.\d+ s of control time", reviewed.stdout)

    as_json = subprocess.run([sys.executable, "-m", "hil", "review", str(save), "--json"],
                             capture_output=True, text=True, timeout=120)
    document = json.loads(as_json.stdout)
    assert document["faults"] == 1
    (run,) = document["runs"]
    assert run["cycles"] > 1000 and run["duration_s"] > 2
    assert set(run["joints"]) >= {"arm_rot_1", "arm_rot_2"}
    assert all(j["rms"] <= j["max"] for j in run["joints"].values())

    port = free_port()
    log = tmp_path / "web.log"           # a file, not a pipe: a viewer left running would
    with open(log, "w") as output:       # hold a pipe open and hang the reader
        web = subprocess.Popen([sys.executable, "-m", "hil", "review", str(save), "--web",
                                "--web-port", str(port)], stdout=output,
                               stderr=subprocess.STDOUT, text=True)
    try:
        page = _fetch_when_up(f"http://127.0.0.1:{port}/")
        assert "rerun" in page.lower()
        assert f"web viewer at http://127.0.0.1:{port}/" in log.read_text()
    finally:
        web.send_signal(signal.SIGINT)   # Ctrl-C: hil review stops the viewer it started
        try:
            ended = web.wait(60)
        except subprocess.TimeoutExpired:
            web.kill()
            ended = web.wait()
        left = subprocess.run(["pgrep", "-f", f"--web-viewer-port {port}"],
                              capture_output=True, text=True).stdout.split()
        for pid in left:
            os.kill(int(pid), signal.SIGKILL)
    assert ended == 0 and not left, (ended, left, log.read_text()[-2000:])


def test_review_of_nothing_says_what_it_looked_for(tmp_path):
    missing = subprocess.run([sys.executable, "-m", "hil", "review", str(tmp_path / "x.rrd")],
                             capture_output=True, text=True, timeout=60)
    assert missing.returncode == 1 and "Traceback" not in missing.stderr
    assert "no recording" in missing.stderr and "x-0001.rrd" in missing.stderr


#: a recording's bound (issue 32): bytes a second of run, every signal of every cycle
RECORDING_BYTES_PER_SECOND = 0.15e6


@pytest.mark.slow
def test_a_recording_holds_every_cycle_of_every_signal_in_its_byte_budget(tmp_path):
    """10 s of the pigot in lock-step (deterministic: every cycle the controller ran, 500 Hz,
    its 7 axes): read back with rerun's dataframe API, every cycle is one row on the three
    timelines with every signal, and the file holds at most RECORDING_BYTES_PER_SECOND."""
    import rerun.chunk

    save = tmp_path / "run.rrd"
    result = subprocess.run([sys.executable, "-m", "hil", "up", "pigot", "--lock-step",
                             "--duration", "10", "--no-viewer", "--save", str(save)],
                            capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert result.returncode == 0, result.stdout + result.stderr
    recorded = int(re.search(r"recorded (\d+) cycles in \d+ batches, 0 lost",
                             result.stdout).group(1))
    store = rerun.chunk.RrdReader(save).store().stream().collect()
    table = store.reader(index="control_time", contents=AXIS_ENTITY).to_arrow_table()
    assert table.num_rows == recorded >= 4500
    control = np.array(table.column("control_time").cast("int64").to_pylist())
    assert set(np.diff(control)) == {2_000_000}                 # no cycle missing, in ns
    for timeline in ("wall_time", "sim_time"):
        assert table.column(timeline).null_count == 0, timeline
    values = np.array(table.column(f"{AXIS_ENTITY}:Scalars:scalars").to_pylist(), dtype=float)
    assert values.shape == (recorded, 7 * 6 + 7 + 2)
    assert not np.isnan(values[:, :-2]).any()                   # the loop's: NaN in lock-step
    per_second = save.stat().st_size / (recorded * 0.002)
    print(f"{save.stat().st_size / 1e6:.2f} MB for {recorded} cycles: "
          f"{per_second / 1e6:.3f} MB a second of run")
    assert per_second <= RECORDING_BYTES_PER_SECOND


def _fetch_when_up(url: str, within: float = 30.0) -> str:
    """The page at ``url`` once its server answers."""
    deadline = time.monotonic() + within
    while True:
        try:
            with urllib.request.urlopen(url, timeout=5) as answer:
                return answer.read().decode(errors="replace")
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.2)



def test_a_previous_runs_outputs_are_named_before_they_are_replaced_and_its_segments_go(
        tmp_path):
    """Issue 64: `hil up` overwrote run.rrd and run.can.blf without a word. It replaces them
    as rerun's own save does (its names are fixed: the README's `hil up pigot --demo` runs
    again and again) and names each first (hil.cli.up.outputs); a previous run's segments
    are removed, as `hil review run.rrd` would read them as this run's."""
    from hil.cli.up.outputs import replace_previous
    from hil.visualisation.segments import segment_files

    save, can_log, logs = tmp_path / "run.rrd", tmp_path / "run.can.blf", tmp_path / "run.logs"
    assert replace_previous(save, can_log, logs) == []              # a first run: nothing
    save.write_bytes(b"x" * 2_000_000)
    can_log.write_bytes(b"y" * 300_000)
    for number in (1, 2):
        (tmp_path / f"run-000{number}.rrd").write_bytes(b"z")
    logs.mkdir()
    (logs / "sim.log").write_text("before")
    said = replace_previous(save, can_log, logs)
    assert said[0].startswith(f"{save} (2.0 MB, ") and said[1].startswith(f"{can_log} (0.3 MB, ")
    assert said[2:] == ["2 segment(s) run-0001.rrd ... run-0002.rrd",
                        f"the process logs in {logs}/"]
    assert segment_files(save) == [save]              # review finds this run's file alone
