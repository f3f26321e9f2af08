"""``hil bench``, across processes: the stack as users run it.

Each run starts ``hil sim`` and ``hil control`` (and, in the runs "with viz", ``hil viz``
recording a file and the CAN log) as separate processes on the Zenoh CAN transport over
loopback, in real time, placed on the CPUs as ``hil up`` places them (or in lock-step, as
``hil up --lock-step`` runs them: the speed-up over real time), for a while, stops
them as ``hil up`` does and reads the controller's own report (``hil control --report``):
period error, missed cycles, busy time, the round trip from each cycle's last frame to its
last answer, faults; and each process' CPU share from /proc. Beside each, the floor of the
same transport (:mod:`hil.bench.floor`).

Rates above a config's own are run on buses of proportionally higher bitrate (the load
stays what the config has at its rate; the transport has no bitrate of its own).
"""

from __future__ import annotations

import json
import math
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import yaml

from hil.bench.floor import cpu_seconds, floor_across_processes
from hil.bench.settings import DID_NOT_START, BenchSettings
from hil.bus_config import load_bus_config
from hil.input_files import read_input_file
from hil.messaging.zenoh_api import ProcessWatch
from hil.supervisor import Child, ChildFailed, Run, cpus_argument, viz_summary
from hil.realtime import LOCK_STEP, REAL_TIME, Timing, lock_step_cpus, real_time_cpus
from hil.zenoh_session import ZenohSettings, close, free_loopback_port, session

#: how long after the controller's bring-up (its first cycle) the measurement starts
SETTLE = 2.0


def across_processes(settings: BenchSettings, say: Callable[[str], None]) -> list[dict]:
    """Every (robot, rate) of ``settings``: the floor, then the stack without and with the
    visualiser."""
    rows = []
    with tempfile.TemporaryDirectory(prefix="hil-bench-configs-") as folder:
        for robot, rate in settings.across_processes:
            path = config_at(settings.config_dir / f"{robot}.yaml", rate, Path(folder))
            say(f"hil bench: {robot} at {rate:g} Hz across processes: the floor ...")
            floor = floor_across_processes(load_bus_config(path), settings.seconds)
            for viz in (False, True):
                say(f"hil bench: {robot} at {rate:g} Hz across processes"
                    f"{', with the visualiser recording' if viz else ''} ...")
                stack = stack_across_processes(path, settings.seconds, viz)
                rows.append({"robot": robot, "rate_hz": rate, "viz": viz, **stack,
                             "floor": floor, "round_trip_p99_over_floor":
                             stack.get("round_trip_p99_us", math.nan)
                             / floor.get("round_trip_p99_us", math.nan)})
    return rows


def config_at(path: Path, rate: float, folder: Path) -> Path:
    """The bus config at ``path`` with every bus at ``rate`` Hz (bitrates scaled with it),
    written into ``folder``."""
    load_bus_config(path)           # a config that is not one: its file, line and what to do
    data = yaml.safe_load(read_input_file(path, "bus config", hint="give a bus_config/*.yaml "
                                          "file", syntax="yaml"))
    data["robot"] = str((path.parent / data["robot"]).resolve())
    for bus in data["buses"]:
        scale = rate / bus["cycle_hz"]
        bus["cycle_hz"] = rate
        if "bitrate" in bus and scale > 1:
            bus["bitrate"] = int(bus["bitrate"] * scale)
    written = folder / f"{path.stem}-{rate:g}hz.yaml"
    written.write_text(yaml.safe_dump(data))
    return written


def lock_step_across_processes(settings: BenchSettings, say: Callable[[str], None]
                               ) -> list[dict]:
    """Each robot of ``settings``' across-processes runs at its config's own rate, in
    lock-step as ``hil up --lock-step`` runs and places it (no visualiser), beside the same
    frames exchanged as fast as they are answered between two bare processes placed alike."""
    rows = []
    for robot in dict.fromkeys(robot for robot, _ in settings.across_processes):
        path = settings.config_dir / f"{robot}.yaml"
        config = load_bus_config(path)
        say(f"hil bench: {robot} in lock-step across processes: the floor ...")
        floor = floor_across_processes(config, settings.seconds, paced=False)
        say(f"hil bench: {robot} in lock-step across processes ...")
        stack = stack_across_processes(path, settings.seconds, False, LOCK_STEP)
        rows.append({"robot": robot, "rate_hz": config.cycle_hz, **stack, "floor": floor,
                     "speedup_over_floor": stack["speedup_over_real_time"]
                     / floor["speedup_over_real_time"]})
    return rows


def _await_cycling(run: Run, control: Child, endpoint: str, robot: str) -> None:
    """Wait until ``control`` runs its cycles (the liveliness token it declares once its
    bring-up is done), so that a run measures the cycle, not the bring-up: Damiao motors,
    which have no brakes, come up once their swinging joints stand still (5 s for the ur3
    arms of the 1 kHz sweep, against the 2 s the bench gave a banner before)."""
    settings = ZenohSettings(connect=(endpoint,))
    watch = ProcessWatch(session(settings), robot)
    try:
        run.wait_until(control, lambda timeout: watch.wait_alive("control", timeout),
                       "cycling (no liveliness token 'control')")
    finally:
        watch.close()
        close(settings)


def stack_across_processes(config_path: Path, seconds: float, with_viz: bool,
                           timing: Timing = REAL_TIME) -> dict:
    """One run of ``hil sim`` + ``hil control`` (+ ``hil viz``) on the config, placed on the
    CPUs as ``hil up`` places them in that timing (in lock-step, sim and controller on one
    CPU). A real-time run whose child exits (a bring-up the host's stalls failed) is the row
    :data:`DID_NOT_START`."""
    sim_cpus, control_cpus, viz_cpus = (lock_step_cpus() if timing.lock_step
                                        else real_time_cpus())
    timing_options = ["--lock-step"] if timing.lock_step else []
    with tempfile.TemporaryDirectory(prefix="hil-bench-") as folder:
        folder = Path(folder)
        endpoint = f"tcp/127.0.0.1:{free_loopback_port()}"
        report = folder / "control.json"
        children = [Child("sim", ["sim", str(config_path), "--listen", endpoint,
                                  "--status-period", "0", *timing_options,
                                  *cpus_argument(sim_cpus)], folder / "sim.log")]
        if with_viz:
            children.append(Child("viz", ["viz", str(config_path), "--connect", endpoint, "--save",
                                          str(folder / "run.rrd"), "--can-log",
                                          str(folder / "run.can.blf"), *timing_options,
                                          *cpus_argument(viz_cpus)],
                                  folder / "viz.log"))
        children.append(Child("control", ["control", str(config_path), "--connect", endpoint,
                                          "--report", str(report), *timing_options,
                                          *cpus_argument(control_cpus)],
                              folder / "control.log"))
        run = Run(children)
        try:
            for child in children:
                child.start()
                run.wait_for_line(child, f"hil {child.name}:")
            _await_cycling(run, children[-1], endpoint, load_bus_config(config_path).robot.name)
            time.sleep(SETTLE)
            cpu_start = {child.name: cpu_seconds(child.pid) for child in children}
            run.wait(seconds)
            cpu = {child.name: (cpu_seconds(child.pid) - cpu_start[child.name]) / seconds
                   for child in children}
        except ChildFailed as failure:
            if timing.lock_step:        # no stall of the host fails a lock-step run
                raise
            return {DID_NOT_START: str(failure)}
        finally:
            problems = run.shut_down()
        if not report.exists():
            raise RuntimeError(f"hil control wrote no report ({'; '.join(problems)}):\n"
                               f"{children[-1].last_lines()}")
        figures = json.loads(report.read_text())
        recorded = viz_summary(children[1]) if with_viz else None
    lost = sum(bus.get("lost", 0) for bus in figures.pop("buses", {}).values())
    return {**figures, "faults": len(figures.get("faults", [])),
            "first_fault": (figures.get("faults") or [None])[0], "frames_lost": lost,
            "cpu": {name: round(share, 3) for name, share in cpu.items()},
            **({"recorded": recorded} if recorded else {})}

