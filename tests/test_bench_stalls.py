"""A bench that breaks real time says so: drives found silent while the simulator was
stopped are put down to the stall it measured, with a distinct exit status, and a drive
silenced on purpose stays a device fault. The stalls are made on purpose (SIGSTOP), 2.5x
the silence limit of a 500 Hz controller: nothing here asserts a timing of the host."""

from __future__ import annotations

import dataclasses
import math
import os
import re
import signal
import subprocess
import time

import can
import pytest

from hil.control_node.attribution import GRACE, FaultAttribution
from hil.hardware import AxisFault, FaultKind
from hil.realtime.stalls import Stall, StallDetector
from hil.zenoh_session import ZenohSettings
from hil.cli.run_progress import Progress
from conftest import linked
from test_up import hil, read_rrd

#: judged against the host's stalls (tests/host_stalls.py): stalls and silences of real-time runs
pytestmark = pytest.mark.real_time

#: how long the simulator is stopped: 2.5x the controller's silence limit (6 cycles of 2 ms)
STOP = 0.030


def _silent(node: int, silent_for: float | None = 0.012) -> AxisFault:
    return AxisFault(FaultKind.SILENT, "arm", node, (f"joint{node}",), f"node {node} silent",
                     silent_for=silent_for)


def test_a_stall_over_the_silence_window_explains_the_silences_found_in_it():
    attribution = FaultAttribution(period=0.002, silence_cycles=6)
    attribution.fault(_silent(1), 100.012)
    attribution.fault(_silent(2), 100.012)
    attribution.fault(AxisFault(FaultKind.FAULT, "arm", 3, ("joint3",), "in FAULT"), 100.012)
    assert attribution.attributions(100.013) == []          # no stall reported yet
    attribution.stall(Stall("control", 100.001, 0.009))     # the controller waited meanwhile
    attribution.stall(Stall("sim", 100.0, 0.030, 0.0))      # reported once it ended
    assert attribution.attributions(100.040) == []          # others may still report
    explained, = attribution.attributions(100.012 + GRACE)
    assert [f.node_id for f in explained.faults] == [1, 2]  # a drive's own fault never is
    assert [s.process for s in explained.stalls] == ["sim", "control"]
    assert "the simulator stalled 30 ms" in explained.message()
    assert dict(explained.values())["explains"] == "2"
    assert attribution.attributions(100.050 + GRACE) == []  # each fault explained once


def test_stalls_far_from_a_silence_or_too_short_explain_nothing():
    attribution = FaultAttribution(period=0.002, silence_cycles=6)
    attribution.fault(_silent(1), 100.0)
    attribution.stall(Stall("sim", 99.5, 0.030))             # ended long before
    attribution.stall(Stall("control", 99.995, 0.003))       # under two cycles
    attribution.stall(Stall("sim", 100.5, 0.030))            # after it was found
    attribution.stall(Stall("control", 100.0005, 0.012))     # reporting it took time
    assert attribution.attributions(100.0 + GRACE) == []
    assert attribution.attributions(106.0) == [] and not attribution.waiting   # forgotten


def test_a_short_stall_late_inside_a_long_silence_does_not_explain_it():
    attribution = FaultAttribution(period=0.002, silence_cycles=6)
    attribution.fault(_silent(2, silent_for=0.3), 100.0)     # a heartbeat gone for 300 ms
    attribution.stall(Stall("control", 99.99, 0.008))
    assert attribution.attributions(100.0 + GRACE) == []
    attribution.fault(_silent(3, silent_for=0.3), 101.0)
    attribution.stall(Stall("sim", 100.69, 0.35, resolution=0.01))    # it was under way
    explained, = attribution.attributions(101.0 + GRACE)
    assert [f.node_id for f in explained.faults] == [3]


def test_a_watchdog_trip_during_a_stall_as_long_as_its_timeout_is_the_benchs():
    """A drive's RPDO watchdog (EMCY 0x8250) trips when the controller's frames stop coming:
    during a 115 ms stall of the controller, that is the bench's; a stall too short to trip
    a 100 ms watchdog, or a following error, is not."""
    attribution = FaultAttribution(period=0.002, silence_cycles=6,
                                   link_timeouts={("arm", 1): 0.1, ("arm", 2): 0.1})
    tripped = AxisFault(FaultKind.QUICK_STOP, "arm", 1, ("joint1",),
                        "quick-stopped on its own after EMCY 0x8250", 0x8250)
    following = AxisFault(FaultKind.FAULT, "arm", 2, ("joint2",), "in FAULT", 0x8611)
    attribution.fault(tripped, 100.117)
    attribution.fault(following, 100.117)
    attribution.stall(Stall("control", 100.0, 0.115))
    explained, = attribution.attributions(100.117 + GRACE)
    assert explained.faults == (tripped,)
    assert "drive fault(s) of lost frames (arm/1)" in explained.message()
    attribution.fault(tripped, 200.117)
    attribution.stall(Stall("transport", 200.09, 0.020))   # too short for a 100 ms watchdog
    assert attribution.attributions(200.117 + GRACE) == []


def test_a_burst_of_late_deliveries_explains_every_drive_in_one_line():
    attribution = FaultAttribution(period=0.002, silence_cycles=6)
    for node in range(1, 7):
        attribution.fault(_silent(node), 100.014)
    for i, where in enumerate(["ur3/arm", "ur3/wrist"] * 3):
        attribution.stall(Stall("transport", 100.0 + i * 0.001, 0.013 + i * 0.001, where=where))
    explained, = attribution.attributions(100.014 + GRACE)
    assert len(explained.faults) == 6 and len(explained.stalls) == 6
    assert ("the Zenoh transport delivered 6 messages late from" in explained.message()
            and "up to 18 ms (ur3/arm, ur3/wrist)" in explained.message())
    assert dict(explained.values())["explains"] == "6"


def test_a_slow_link_that_held_the_answers_explains_the_silences_and_is_named():
    attribution = FaultAttribution(period=0.002, silence_cycles=6)
    for node in (1, 2, 3):
        attribution.fault(_silent(node), 100.014)       # silent since 100.002
    # the link's round trips as the transport measured them, one stall per stretch: the one
    # under way when the silence began explains it, the next (after it) does not
    for start in (99.99, 100.03):
        attribution.stall(Stall("link", start, 0.040, where="ur3/arm"))
    explained, = attribution.attributions(100.014 + GRACE)
    assert len(explained.faults) == 3 and [s.at for s in explained.stalls] == [99.99]
    assert explained.message().startswith("bench fault, not a drive fault: the link of ur3/arm "
                                          "took 40 ms a round trip at")


def test_the_detector_measures_a_late_wake_up_and_the_steal_around_it():
    ticks = iter([10.0, 10.010, 10.045])
    steals = iter([5.0, 5.012])           # read at the start and at the stall only
    detector = StallDetector("sim", 0.010, clock=lambda: next(ticks), wall=lambda: 1000.0,
                             steal=lambda: next(steals))
    assert detector.tick() is None and detector.tick() is None
    stall = detector.tick()
    assert stall.length == pytest.approx(0.025) and stall.steal == pytest.approx(0.012)
    assert stall.steal_window == pytest.approx(0.045) and stall.at == pytest.approx(
        1000.0 - 0.025)
    assert "hypervisor steal 12 ms in the 45 ms around it" in str(stall)
    # heard over Zenoh (hil_msgs/Stall carries no window): the steal, and no "nan ms"
    heard = dataclasses.replace(stall, steal_window=math.nan)
    assert "(hypervisor steal 12 ms around it)" in str(heard)
    assert detector.count == 1 and detector.late(math.nan) is None


def _up(tmp_path, *extra: str, duration: str = "6") -> subprocess.Popen:
    return hil("up", "ur3", "--real-time", "--no-viewer", "--duration", duration, "--save",
               str(tmp_path / "run.rrd"), *extra, cwd=tmp_path)


def _stop_the_sim_once(up: subprocess.Popen, once: str = "control ready",
                       settle: float = 1.5) -> tuple[str, str]:
    """``settle`` s after ``up`` prints a line holding ``once`` (by default: after the
    controller is up, once it cycles), stop its simulator for STOP; the run's output."""
    try:
        sim = None
        for line in up.stdout:
            found = re.search(r"sim ready \(pid (\d+)\)", line)
            sim = int(found.group(1)) if found else sim
            if once in line:
                break
        assert sim is not None, "hil up named no simulator"
        time.sleep(settle)
        try:
            os.kill(sim, signal.SIGSTOP)
            time.sleep(STOP)
            os.kill(sim, signal.SIGCONT)
        except ProcessLookupError:               # --max-stalls may have ended the run already
            pass
        return up.communicate(timeout=120)
    finally:
        if up.poll() is None:
            up.kill()
            up.communicate()


needs_sigstop = pytest.mark.skipif(not hasattr(signal, "SIGSTOP"),
                                   reason="no SIGSTOP on this platform")


@needs_sigstop
def test_a_stopped_simulator_is_named_as_the_bench_fault_and_ends_with_the_bench_status(
        tmp_path):
    # one stall of the sim, or several ("stalled 2 times from ..., up to 31 ms")
    sim_named = re.compile(r"WARN: bench fault, not a drive fault: .*the simulator stalled "
                           r"(?:(\d+) ms|\d+ times from [\d:.]+, up to (\d+) ms)")
    # measured from the simulator's own 10 ms wake-ups: at least the stop less one period
    stop_ms = 1e3 * STOP - 10
    for attempt in (1, 2, 3):
        # a loaded host's own stall in the 1.5 s before the stop (CI runs: Zenoh deliveries
        # 16-20 ms late, the simulator 12 ms late) faulted the drives first, and was named for
        # it, rightly: the stop then faulted nothing more. Such a run says nothing of the
        # stop: the scenario runs again
        folder = tmp_path / f"run{attempt}"
        folder.mkdir()
        up = _up(folder)
        out, err = _stop_the_sim_once(up)
        stop_named = [m for m in sim_named.finditer(err)
                      if int(m.group(1) or m.group(2)) >= stop_ms]
        if stop_named or "bench fault, not a drive fault" not in err:
            break
    assert up.returncode == 3, out[-3000:] + err[-3000:]
    assert re.search(r"ERROR: drive node \d \(joint\d\) on bus '\w+' is silent", err), err
    assert stop_named, err[-3000:]
    assert "the bench broke real time" in err
    assert re.search(r"hil up: the bench since the controller's bring-up: stalls over 5 ms: "
                     r".*sim [1-9]", out), out[-2000:]
    rows, static = read_rrd(folder / "run.rrd")            # on the control loop's view
    assert rows["/loop/stalls/sim"] >= 1 and "/loop/stalls/sim" in static, rows


@needs_sigstop
def test_a_stall_just_before_the_run_ends_is_still_named_as_the_bench_fault(tmp_path):
    # the run ends within the attribution's grace after the silence it caused: the
    # controller, stopping, waits for the stall's report instead of leaving it unexplained
    for attempt in (1, 2, 3):
        # the stop is timed by hil up's progress line, 0.3 s before the end: on a loaded host
        # (a CI run with host stalls up to 152 ms ended once with the silence unexplained)
        # the line, or the simulator's report, can come late enough to put the stop into
        # the shut-down, where the simulator is ended before it reports. Such a run says
        # nothing of the end's grace: the scenario runs again
        folder = tmp_path / f"run{attempt}"
        folder.mkdir()
        up = _up(folder, duration="1.3")
        out, err = _stop_the_sim_once(up, once="[   1.0 s]", settle=0.0)
        if "WARN: bench fault, not a drive fault: " in err:
            break
    assert up.returncode == 3, out[-3000:] + err[-3000:]
    assert "WARN: bench fault, not a drive fault: " in err and "the simulator stalled" in err


@needs_sigstop
def test_max_stalls_stops_the_run_at_the_stall_past_the_limit(tmp_path):
    up = _up(tmp_path, "--max-stalls", "0")
    out, err = _stop_the_sim_once(up)
    assert up.returncode == 3, out[-3000:] + err[-3000:]
    assert "the bench stalled more than --max-stalls 0 times (the last: " in err, err[-3000:]
    assert "run stopped, exit status 3" in err


def test_the_tally_counts_each_process_and_a_limit_calls_once_past_it():
    calls = []
    progress = Progress(max_stalls=1, on_too_many=lambda: calls.append(1))
    progress.on_stall(Stall("sim", time.time() - 60, 0.030))       # in the bring-up
    progress.count_stalls()
    assert progress.stalls.total == 0
    progress.on_stall(Stall("sim", time.time(), 0.030))
    assert calls == [] and progress.too_many is None
    progress.on_stall(Stall("transport", time.time(), 0.007, where="ur3/arm"))
    progress.on_stall(Stall("sim", time.time(), 0.012))
    assert calls == [1] and progress.too_many.process == "transport"
    assert progress.stalls.figures() == {"sim": {"count": 2, "longest_ms": 30.0},
                                         "transport": {"count": 1, "longest_ms": 7.0}}
    assert progress.stalls.summary() == ("stalls over 5 ms: sim 2 (longest 30 ms), "
                                         "transport 1 (longest 7 ms)")


def test_a_drive_silenced_on_purpose_is_a_device_fault_the_bench_does_not_explain(tmp_path):
    up = _up(tmp_path, "--fault", "silence:arm/1@1")
    out, err = up.communicate(timeout=120)
    assert up.returncode == 1, out[-3000:] + err[-3000:]
    # its heartbeat stays away for good: whatever stall of the bench coincides with its first
    # missed answers (one is named if measured), this silence is no stall's
    assert "drive node 1 (joint1) on bus 'arm' is silent: not heard for" in err, err
    assert re.search(r"fault\(s\), above, [1-9]\d* of them not explained by a stall of the "
                     r"bench", err), err


@pytest.fixture
def arm_bus(watched_robot):
    """The ur3's arm bus over the watched robot's Zenoh, and the settings of its session."""
    endpoint, _ = watched_robot
    settings = ZenohSettings(connect=(endpoint,))
    bus = can.Bus(interface="zenoh", channel="ur3/arm", settings=settings)
    yield bus, settings
    bus.shutdown()


@needs_sigstop
def test_a_bring_up_that_fails_while_the_simulator_is_stopped_is_told_as_the_benchs(
        tmp_path, processes, watched_robot, arm_bus):
    """The simulator stopped from before the controller's release until half a second past
    its boot wait, counted from the controller's first reset seen on the bus (a slow host
    may take a while to begin the bring-up): no drive is heard, the bring-up fails, and the
    simulator's stall (reported once it resumes, within the grace the controller waits)
    explains it: exit status 3."""
    endpoint, watch = watched_robot
    bus, bus_settings = arm_bus
    boot = 1.0
    sim = hil("sim", "ur3", "--connect", endpoint, "--status-period", "0", cwd=tmp_path)
    processes.append(sim)
    assert watch.wait_alive("sim", 60), sim.stderr.read()
    control = hil("control", "ur3", "--connect", endpoint, "--hold", "--boot-timeout",
                  f"{boot:g}", stdin=subprocess.PIPE, cwd=tmp_path)
    processes.append(control)
    assert linked(bus_settings, "ur3", "control/held"), control.stderr.read()
    os.kill(sim.pid, signal.SIGSTOP)
    try:
        control.stdin.write("\n")
        control.stdin.flush()
        deadline = time.monotonic() + 60
        while (frame := bus.recv(1.0)) is None or frame.arbitration_id != 0x000:  # NMT
            assert time.monotonic() < deadline, "the controller sent no reset"
        time.sleep(boot + 0.5)
    finally:
        os.kill(sim.pid, signal.SIGCONT)
    out, err = control.communicate(timeout=60)
    assert control.returncode == 3, out + err
    assert f"not heard within {boot:g} s after reset" in err, err
    named = re.search(r"the bench itself stalled during the bring-up: .*the simulator "
                      r"stalled (\d+) ms", err)
    assert named and int(named.group(1)) >= 1e3 * boot, err
    assert "Traceback" not in err
