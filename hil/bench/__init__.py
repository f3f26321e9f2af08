"""``hil bench``: how fast and how faithful the stack is, measured in one run.

Every figure comes from the same process and the same minutes, so ratios
hold on a noisy machine. The stacks run in-process on ``hil-virtual``
(python-can's virtual bus, frames handed over in the sender's thread;
SocketCAN vcan where the kernel has it), with the real
simulator, CAN master, trajectory controller and Zenoh publications on
loopback.

Figures (each a list of rows; a figure that cannot be measured here says why):

* ``control_cycle``: real-time period statistics per robot and rate (period
  from release to release, busy time, the loop's scheduling), and the sim's
  real-time factor over the same run;
* ``timing_floor``: the same pacing with nothing to do, at the highest rate:
  what this machine's scheduler and timers allow any loop;
* ``socketcan``: the same over vcan, or why not;
* ``lock_step``: speed-up over real time, full-stack time per cycle;
* ``overhead``: that time against a bare python-can exchange of the same
  frames on the same kind of bus, and against the bare MuJoCo steps;
* ``latency``: from a setpoint leaving the trajectory controller to the
  joint state it causes arriving on Zenoh;
* ``tracking``: RMS and max error on a fixed trajectory, against MuJoCo's
  ideal position servo on the same model following the same reference;
* ``bus_load``: measured on the bus against the bitrate, with the config's
  worst-case estimate;
* ``fault_detection``: for each injected fault kind, whether and how fast
  the controller reported it;
* ``across_processes``: ``hil sim`` and ``hil control`` (and ``hil viz``) as separate
  processes over the Zenoh CAN transport, beside the floor of that transport measured in
  the same run (:mod:`hil.bench.processes`);
* ``lock_step_across_processes``: the same in lock-step, beside its floor;
* ``scale``: the CPU a cycle costs the sim and the controller for robots of 6 to 34
  drives, and whether each holds its rate across processes (:mod:`hil.bench.scale`).

``run_soak`` repeats a trajectory for a long time and reports drift, memory
growth and missed cycles.
"""


from __future__ import annotations

import os
import platform
import tempfile
from collections.abc import Callable
from pathlib import Path

import hil.drives.core as core_module
from hil.bench.faults import fault_detection
from hil.bench.lock_step import LOCK_STEP_WINDOW, bare_mujoco, bare_python_can, lock_step
from hil.bench.processes import across_processes, lock_step_across_processes
from hil.bench.real_time import real_time, socketcan, timing_floor, vcan_missing
from hil.bench.scale import scale
from hil.bench.settings import (
    ACROSS_PROCESSES, ACROSS_PROCESSES_QUICK, DID_NOT_START, FIGURES, RATES, ROBOTS,
    BenchSettings, with_feed_forward, with_rate,
)
from hil.bench.soak import run_soak
from hil.bench.tracking import tracking, tracking_goal
from hil.bus_config import load_bus_config
from hil.compiled import is_compiled
from hil.stack import IN_PROCESS
from hil.zenoh_session import close_all

__all__ = ["ACROSS_PROCESSES", "ACROSS_PROCESSES_QUICK", "DID_NOT_START", "FIGURES",
           "LOCK_STEP_WINDOW", "RATES", "ROBOTS", "BenchSettings", "run_bench", "run_scale",
           "run_soak", "runs_not_started", "scale_not_started", "tracking_goal", "with_rate"]


def _machine() -> dict:
    """What the figures depend on besides the code: CPUs, Python, the compiled modules."""
    return {"cpus": len(os.sched_getaffinity(0)), "python": platform.python_version(),
            "platform": platform.platform(),
            # setup.py compiles it where it can: the figures depend on it
            "drive_core": "compiled" if is_compiled(core_module) else "interpreted"}


def run_scale(settings: BenchSettings, say: Callable[[str], None] = print) -> dict:
    """The scale sweep alone (``hil bench --scale``): its rows under ``scale``."""
    return {"machine": _machine(), "settings": {"seconds": settings.seconds},
            "scale": _scale_rows(settings, say)}


def _scale_rows(settings: BenchSettings, say: Callable[[str], None]) -> list[dict]:
    """The scale sweep's rows, its robots made in a folder of their own."""
    with tempfile.TemporaryDirectory(prefix="hil-bench-scale-") as folder:
        return scale(settings, Path(folder), say)


def run_bench(settings: BenchSettings, say: Callable[[str], None] = print) -> dict:
    """Measure every figure; raises RuntimeError if one is missing from the report."""
    report: dict = {"machine": _machine(),
                    "settings": {"seconds": settings.seconds,
                                 "lock_step_cycles": settings.lock_step_cycles}}
    for name in FIGURES:
        report[name] = []
    say(f"hil bench: the timing floor (an empty loop at {max(RATES):g} Hz) ...")
    report["timing_floor"].append(timing_floor(max(RATES), settings.seconds))
    for robot in ROBOTS:
        config = load_bus_config(settings.config_dir / f"{robot}.yaml")
        for rate in RATES:
            say(f"hil bench: {robot} real time at {rate:g} Hz ...")
            cycle, latency, loads = real_time(with_rate(config, rate), settings.seconds)
            report["control_cycle"].append({"robot": robot, "rate_hz": rate,
                                            "transport": IN_PROCESS, **cycle})
            report["latency"].append({"robot": robot, "rate_hz": rate, **latency})
            report["bus_load"] += [{"robot": robot, "rate_hz": rate, **load} for load in loads]
        say(f"hil bench: {robot} lock-step, bare python-can, bare MuJoCo ...")
        stepped = lock_step(config, settings.lock_step_cycles)
        report["lock_step"].append({"robot": robot, "rate_hz": config.cycle_hz, **stepped})
        bare_can = bare_python_can(config, settings.bare_cycles)
        bare_physics = bare_mujoco(config, settings.bare_cycles)
        full = stepped["cycle_us"]
        report["overhead"].append({
            "robot": robot, "full_stack_cycle_us": full, "bare_python_can_cycle_us": bare_can,
            "bare_mujoco_cycle_us": bare_physics, "ratio_to_python_can": full / bare_can,
            "ratio_to_mujoco": full / bare_physics})
        say(f"hil bench: {robot} tracking against MuJoCo's ideal position servo ...")
        fed = tracking(with_feed_forward(config))
        weighed = tracking(with_feed_forward(config, gravity=True))
        keys = ("result", "rms", "max", "rms_per_joint")
        report["tracking"].append({"robot": robot, **tracking(config),
                                   "feed_forward": {key: fed[key] for key in keys},
                                   "gravity_feed_forward": {key: weighed[key] for key in keys}})
    say("hil bench: fault detection (ur3, 500 Hz) ...")
    report["fault_detection"] = fault_detection(
        load_bus_config(settings.config_dir / "ur3.yaml"))
    missing = vcan_missing()
    report["socketcan"] = {"unavailable": missing} if missing else socketcan(settings)
    close_all()
    report["across_processes"] = across_processes(settings, say)
    report["lock_step_across_processes"] = lock_step_across_processes(settings, say)
    report["scale"] = _scale_rows(settings, say)
    absent = [name for name in FIGURES if not report.get(name)]
    if absent:
        raise RuntimeError(f"figures missing from the report: {', '.join(absent)}")
    return report


def runs_not_started(report: dict) -> list[str]:
    """The real-time runs of a report whose stack did not start, each named in words."""
    rows = [(f"{row['robot']} at {row['rate_hz']:g} Hz", row)
            for row in report["control_cycle"]]
    rows += [(f"fault detection: {row['fault']}", row) for row in report["fault_detection"]]
    rows += [(f"{row['robot']} at {row['rate_hz']:g} Hz across processes"
              f"{' with the visualiser' if row['viz'] else ''}", row)
             for row in report["across_processes"]]
    if isinstance(report["socketcan"], list):
        rows += [(f"{row['robot']} over SocketCAN", row) for row in report["socketcan"]]
    return [name for name, row in rows if DID_NOT_START in row] + scale_not_started(
        report["scale"])


def scale_not_started(rows: list[dict]) -> list[str]:
    """The scale sweep's runs whose stack did not start, each named in words."""
    return [f"scale: {row['drives']} drives at {row['rate_hz']:g} Hz" for row in rows
            if DID_NOT_START in row]

