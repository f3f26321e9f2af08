"""tools/plot_scale.py: `hil bench --scale`'s sweep drawn as each process' CPU a cycle
against the drives, hil's master beside a bare one, a panel per rate."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tools"))

import plot_scale  # noqa: E402


def _row(drives: int, rate: float, holds: bool, sim: float, control: float) -> dict:
    return {"drives": drives, "rate_hz": rate, "holds": holds,
            "cpu_us_per_cycle": {"sim": sim, "control": control},
            "bare_master": {"cycles": 1000, "missed": 0 if holds else 50, "drives": drives,
                            "enabled": drives, "cpu_us_per_cycle": {"sim": sim,
                                                                    "control": control / 2}}}


REPORT = {"scale": [_row(6, 500.0, True, 300, 400), _row(12, 500.0, False, 900, 1100),
                    _row(6, 1000.0, True, 250, 300)]}


def test_each_process_is_a_line_per_master_and_a_size_that_did_not_hold_is_marked():
    lines = plot_scale.series(REPORT["scale"], 500.0)
    assert lines[("hil", "control")] == [(6, 400, True), (12, 1100, False)]
    assert lines[("bare", "control")] == [(6, 200, True), (12, 550, False)]


def test_the_tool_writes_an_svg_with_a_panel_per_rate(tmp_path):
    pytest.importorskip("matplotlib", reason="matplotlib (allantools' dependency) is missing")
    report = tmp_path / "bench.json"
    report.write_text(json.dumps(REPORT))
    out = tmp_path / "scale.svg"
    result = subprocess.run([sys.executable, str(ROOT / "tools" / "plot_scale.py"), str(report),
                             "-o", str(out)], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    svg = out.read_text()
    assert svg.startswith("<?xml") and "500 Hz" in svg and "1000 Hz" in svg


def test_a_report_without_a_sweep_is_refused_saying_what_to_run(tmp_path):
    report = tmp_path / "bench.json"
    report.write_text(json.dumps({"lock_step": []}))
    result = subprocess.run([sys.executable, str(ROOT / "tools" / "plot_scale.py"), str(report)],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 1 and "run hil bench --scale first" in result.stderr
