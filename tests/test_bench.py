"""`hil bench --quick`: every figure present, with plausible values."""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys

import pytest

from hil.bench import ACROSS_PROCESSES_QUICK, FIGURES, RATES, ROBOTS
from hil.cli import main
from hil.realtime import CyclePacer

#: judged against the host's stalls (tests/host_stalls.py): `hil bench` measures real time
pytestmark = pytest.mark.real_time


@pytest.mark.slow
def test_quick_bench_reports_every_figure(tmp_path):
    report_path = tmp_path / "bench.json"
    result = subprocess.run([sys.executable, "-m", "hil", "bench", "--quick", "--json",
                             str(report_path)], capture_output=True, text=True, timeout=600,
                            cwd=tmp_path)
    assert result.returncode == 0, result.stdout + result.stderr
    report = json.loads(report_path.read_text())
    for name in FIGURES:
        assert report[name], name
    assert len(report["control_cycle"]) == len(ROBOTS) * len(RATES)
    for row in report["control_cycle"]:
        assert row["cycles"] > 0 and math.isfinite(row["error_p99_us"])
        assert 0.5 < row["sim_real_time_factor"] < 1.5          # real time is real time
        assert 0 < row["busy_p50_us"] <= row["busy_p99_us"] <= row["busy_max_us"]
        assert row["scheduling"].startswith(("SCHED_FIFO", "normal scheduling"))
    floor = report["timing_floor"][0]
    assert floor["rate_hz"] == max(RATES) and floor["cycles"] > 0
    # the empty loop's work is the pacer's own bookkeeping: less than any stack's cycle
    assert floor["busy_p50_us"] < min(row["busy_p50_us"] for row in report["control_cycle"])
    for row in report["latency"]:
        assert row["p50_ms"] > 0 and row["p99_ms"] >= row["p50_ms"]
    for row in report["lock_step"]:
        assert row["windows"] > 0
        assert row["speedup_quiet_quartile"] >= row["speedup_over_real_time"] * 0.9
    for row in report["overhead"]:
        assert row["full_stack_cycle_us"] > row["bare_mujoco_cycle_us"] > 0
        assert row["ratio_to_python_can"] > 1
    for row in report["tracking"]:
        assert row["result"] == "succeeded"
        assert 0 < row["ideal_servo_rms"] and 0 < row["rms"] < 0.05
        assert row["feed_forward"]["result"] == "succeeded"
        assert 0 < row["feed_forward"]["rms"] < row["rms"]
        assert row["gravity_feed_forward"]["result"] == "succeeded"
        assert 0 < row["gravity_feed_forward"]["rms"]
    for row in report["bus_load"]:
        # measured worst-case stuffing never exceeds the config's worst-case estimate, but
        # for the cycles a master late at the window's start runs back to back inside it (up
        # to CyclePacer.RESYNC, then one at the edge): those frames are on the bus then
        window_cycles = row["rate_hz"] * report["settings"]["seconds"]
        catch_up = 1 + (CyclePacer.RESYNC + 1) / window_cycles
        assert 0 < row["measured_load_worst_stuffing"] <= \
            row["estimated_load_worst"] * catch_up, row
    assert len(report["fault_detection"]) == 5
    for row in report["fault_detection"]:
        assert row["detected"] and 0 < row["detection_ms"] < 1000, row
        assert "drive node" in row["first_report"]
    socketcan = report["socketcan"]
    assert isinstance(socketcan, list) or "vcan" in socketcan["unavailable"]
    across = report["across_processes"]
    assert [(r["robot"], r["rate_hz"], r["viz"]) for r in across] == [
        (robot, rate, viz) for robot, rate in ACROSS_PROCESSES_QUICK for viz in (False, True)]
    for row in across:
        assert row["cycles"] > 0 and math.isfinite(row["error_p99_us"]), row
        assert 0 < row["round_trip_p50_us"] <= row["round_trip_p99_us"], row
        floor = row["floor"]
        assert floor["cycles"] > 0 and 0 < floor["round_trip_p50_us"] <= floor["round_trip_p99_us"]
        assert row["round_trip_p99_over_floor"] > 0
        assert set(row["cpu"]) == ({"sim", "control", "viz"} if row["viz"] else {"sim", "control"})
        assert set(floor["cpu"]) == {"sim", "control"} and min(floor["cpu"].values()) >= 0
        if row["viz"]:
            assert " 0 lost" in row["recorded"], row["recorded"]
    stepped = report["lock_step_across_processes"]
    assert [r["robot"] for r in stepped] == [robot for robot, _ in ACROSS_PROCESSES_QUICK]
    for row in stepped:
        # the cycles the controller ran over the seconds it ran them, in the plant's time
        assert row["cycles"] > 0 and row["speedup_over_real_time"] == pytest.approx(
            row["cycles"] / row["rate_hz"] / row["cycling_seconds"])
        assert row["floor"]["speedup_over_real_time"] > 0 and row["faults"] == 0
        assert row["speedup_over_floor"] == pytest.approx(
            row["speedup_over_real_time"] / row["floor"]["speedup_over_real_time"])
        assert set(row["cpu"]) == set(row["floor"]["cpu"]) == {"sim", "control"}
    scale = report["scale"]
    assert [(r["drives"], r["rate_hz"]) for r in scale] == [(6, 500.0), (12, 500.0)]
    for row in scale:
        assert row["cycles"] > 0 and row["buses"] >= row["drives"] // 4
        assert row["cpu_us_per_cycle"]["sim"] > 0 and row["cpu_us_per_cycle"]["control"] > 0
        assert row["holds"] == (row["faults"] == 0 and row["missed"] <= 0.001 * row["cycles"])
        _assert_the_bare_master_enabled_every_drive(row)
    assert "largest that held: 500 Hz" in result.stdout
    assert "lock-step across processes" in result.stdout
    # each process' CPU with the floor's process in its place beside it
    assert re.search(r"sim \d+% \(\d+%\) control \d+% \(\d+%\)", result.stdout), result.stdout
    assert "control cycle, real time" in result.stdout and "tracking" in result.stdout
    assert "across processes" in result.stdout
    assert report["machine"]["drive_core"] in ("compiled", "interpreted")   # read figures by it


@pytest.mark.slow
def test_the_scale_sweep_alone_runs_the_rates_asked_damiao_on_can_fd_from_1_khz(tmp_path):
    """`hil bench --scale 3 --rate 250 --rate 1000`: that robot at those rates, nothing else
    measured, its JSON and its table (issue 69: the sweep is run on its own, at the sizes a
    humanoid has); from 1 kHz the arms are Damiao motors on CAN FD buses (OpenArm's family),
    below it CiA 402 drives on classical CAN, each driven by hil control and by the bare
    python-can master, every motor brought up. (Several sizes in order: the quick bench's.)"""
    report_path = tmp_path / "scale.json"
    result = subprocess.run([sys.executable, "-m", "hil", "bench", "--scale", "3", "--rate",
                             "250", "--rate", "1000", "--seconds", "1s", "--json",
                             str(report_path)], capture_output=True, text=True, timeout=300,
                            cwd=tmp_path)
    assert result.returncode == 0, result.stdout + result.stderr
    report = json.loads(report_path.read_text())
    assert set(report) == {"machine", "settings", "scale"}
    slow, fast = report["scale"]
    assert [(r["drives"], r["rate_hz"], r["buses"]) for r in (slow, fast)] == [
        (3, 250.0, 1), (3, 1000.0, 1)]
    assert (slow["protocol"], slow["fd"], fast["protocol"], fast["fd"]) == (
        "cia402", False, "damiao", True)
    # measured once the controller cycles (its bring-up waits for the swinging arm to rest)
    assert fast["cycles"] >= 1000, fast
    for row in (slow, fast):
        assert row["cycles"] > 0 and row["cpu_us_per_cycle"]["control"] > 0, row
        _assert_the_bare_master_enabled_every_drive(row)
    assert result.stdout.startswith("scale (ur3 arms on one base")
    assert "largest that held: 250 Hz" in result.stdout
    assert re.search(r"(yes|no)\s+\d+\s+\d+\s+\d+ 3/3", result.stdout), result.stdout


def _assert_the_bare_master_enabled_every_drive(row: dict) -> None:
    """A scale row's bare python-can master (hil.bench.bare_master) brought every drive of
    the robot up to OPERATION ENABLED and cycled it, its CPU and the sim's measured."""
    bare = row["bare_master"]
    assert bare["drives"] == row["drives"] and bare["enabled"] == bare["drives"], bare
    assert bare["cycles"] > 0 and bare["cpu_us_per_cycle"]["sim"] > 0, bare
    assert bare["cpu_us_per_cycle"]["control"] > 0, bare


def test_the_scale_sweeps_options_are_refused_where_they_mean_nothing(capsys):
    assert main(["bench", "--rate", "500"]) == 1          # a usage error, as hil says them
    assert "--rate is for --scale" in capsys.readouterr().err
    assert main(["bench", "--scale", "6", "--soak", "10s"]) == 1
    assert "two benches" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["bench", "--scale", "6,0"])
    assert "each drive count must be 1 or more" in capsys.readouterr().err


@pytest.mark.slow
def test_soak_repeats_the_trajectory_and_reports_drift_memory_and_missed_cycles(tmp_path):
    report_path = tmp_path / "soak.json"
    result = subprocess.run([sys.executable, "-m", "hil", "bench", "--soak", "6s", "--json",
                             str(report_path)], capture_output=True, text=True, timeout=300,
                            cwd=tmp_path)
    assert result.returncode == 0, result.stdout + result.stderr
    soak = json.loads(report_path.read_text())["soak"]
    assert soak["repetitions"] >= 1 and soak["cycles"] > 0
    # a repetition may fail on this shared machine's timing: it is counted, with its reason
    timeline = soak["timeline"]
    assert soak["failed"] == sum(r["result"] != "succeeded" for r in timeline)
    assert all(r["reason"] for r in timeline if r["result"] != "succeeded")
    assert all(r["final_error"] < 0.02 for r in timeline if r["result"] == "succeeded")
    assert {"rss_growth_bytes", "rss_growth_after_first_bytes", "missed", "timeline"} <= set(soak)
    assert "memory growth" in result.stdout
