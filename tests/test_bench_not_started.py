"""A real-time run of `hil bench` whose stack does not start (a host stalling past the drives'
silence limits) is a row of the report that says why, the other runs are still measured, and
the command names it and exits 3, with no traceback. Stacks are made to fail on purpose:
nothing here runs in real time."""

from __future__ import annotations

import copy
import importlib
import json
from pathlib import Path

import pytest

import hil.cli.bench
from hil.bench import DID_NOT_START, BenchSettings, runs_not_started
from hil.bench.faults import fault_detection
from hil.bench.processes import stack_across_processes
from hil.bench.real_time import real_time, socketcan
from hil.bus_config import load_bus_config
from hil.cli import main
from hil.realtime.stalls import BENCH_STALL_STATUS
from hil.resources import BUS_CONFIGS, data_dir
from hil.realtime import LOCK_STEP
from hil.stack import StackDidNotStart
from hil.supervisor import ChildFailed

#: a whole report of `hil bench --quick` as it ran on a 2-vCPU host (AMD EPYC, 2026-11-29)
REPORT = Path(__file__).parent / "fixtures" / "bench_report.json"
WHY = "the stack did not start in 3 attempts: silent | silent | silent"


@pytest.fixture
def stacks_do_not_start(monkeypatch):
    def running_stack(*args, **kwargs):
        raise StackDidNotStart(WHY)

    # the modules, not hil.bench's functions of the same names
    for name in ("hil.bench.real_time", "hil.bench.faults"):
        monkeypatch.setattr(importlib.import_module(name), "running_stack", running_stack)


def test_each_real_time_figure_keeps_a_row_that_says_its_stack_did_not_start(
        stacks_do_not_start):
    config = load_bus_config(data_dir(BUS_CONFIGS) / "ur3.yaml")
    cycle, latency, loads = real_time(config, 2.0)
    assert cycle == {DID_NOT_START: WHY} and "did not start" in latency["unavailable"]
    assert loads == []
    rows = fault_detection(config)
    assert len(rows) == 5 and all(row[DID_NOT_START] == WHY and not row["detected"]
                                  for row in rows)
    assert [row[DID_NOT_START] for row in socketcan(BenchSettings.quick())] == [WHY, WHY]


class _ControllerExitsAtBringUp:
    """hil.bench.processes' Run and Child, where the controller exits as a failed real-time
    bring-up makes it: no process is started."""

    def __init__(self, children, *args):
        self.children = children

    def wait_for_line(self, child, text):
        if child.name == "control":
            raise ChildFailed("hil control (pid 1) exited with status 1; its last lines: "
                              "error: drive node 1 does not answer SDO")

    def shut_down(self):
        return []


def test_a_run_across_processes_whose_controller_exits_at_bring_up_is_a_row_that_says_why(
        monkeypatch, tmp_path):
    processes = importlib.import_module("hil.bench.processes")
    monkeypatch.setattr(processes, "Run", _ControllerExitsAtBringUp)
    monkeypatch.setattr(processes.Child, "start", lambda child: None)
    config = data_dir(BUS_CONFIGS) / "ur3.yaml"
    row = stack_across_processes(config, 2.0, with_viz=True)
    assert row == {DID_NOT_START: "hil control (pid 1) exited with status 1; its last lines: "
                                  "error: drive node 1 does not answer SDO"}
    with pytest.raises(ChildFailed):       # in lock-step no stall of the host explains it
        stack_across_processes(config, 2.0, False, LOCK_STEP)


@pytest.fixture
def report_with(monkeypatch, tmp_path):
    """`hil bench` run on a given report; (exit status, stdout, stderr, report written)."""
    def run(report: dict, capsys) -> tuple[int, str, str, dict]:
        monkeypatch.setattr(hil.cli.bench, "run_bench", lambda settings, say: report)
        written = tmp_path / "bench.json"
        status = main(["bench", "--quick", "--json", str(written)])
        out, err = capsys.readouterr()
        return status, out, err, json.loads(written.read_text())

    return run


def test_hil_bench_names_the_runs_that_did_not_start_and_exits_3(report_with, capsys):
    report = json.loads(REPORT.read_text())
    assert runs_not_started(report) == []
    failed = copy.deepcopy(report)
    failed["control_cycle"][3] = {"robot": "pigot", "rate_hz": 250.0, DID_NOT_START: WHY}
    failed["latency"][3] = {"robot": "pigot", "rate_hz": 250.0, "unavailable": "not started"}
    failed["fault_detection"][1].update(detected=False, detection_ms=None, first_report=None,
                                        **{DID_NOT_START: WHY})
    failed["across_processes"][1] = {"robot": "ur3", "rate_hz": 500.0, "viz": True,
                                     DID_NOT_START: "hil control exited"}
    failed["scale"][1] = {"drives": 12, "rate_hz": 500.0, "buses": 3, "holds": False,
                          DID_NOT_START: "hil control exited"}
    status, out, err, written = report_with(failed, capsys)
    assert status == BENCH_STALL_STATUS == 3
    assert written == failed
    assert f"pigot    250 {hil.cli.bench.NOT_STARTED}" in out
    assert f"delay answers 200 ms   {hil.cli.bench.NOT_STARTED}" in out
    assert f"ur3        500  yes {hil.cli.bench.NOT_STARTED}" in out
    assert f"    12   500     3 {hil.cli.bench.NOT_STARTED}" in out
    assert "ur3      500    1000" in out                  # the runs that started, measured
    assert "largest that held: 500 Hz 6 drives" in out
    assert ("4 real-time run(s) did not start: pigot at 250 Hz, fault detection: delay "
            "answers 200 ms, ur3 at 500 Hz across processes with the visualiser, scale: 12 "
            "drives at 500 Hz") in err
    assert "Traceback" not in err


def test_hil_bench_with_every_run_started_exits_0(report_with, capsys):
    status, out, err, _ = report_with(json.loads(REPORT.read_text()), capsys)
    assert status == 0 and "did not start" not in out + err


def test_a_lock_step_run_that_does_not_start_is_an_error_not_a_traceback(monkeypatch, capsys):
    def run_bench(settings, say):
        raise StackDidNotStart(WHY)

    monkeypatch.setattr(hil.cli.bench, "run_bench", run_bench)
    assert main(["bench", "--quick"]) == 1
    assert capsys.readouterr().err.strip() == f"hil bench: error: {WHY}"
