"""Where a lock-step cycle across processes goes (a benchmark, not a test): the robot's
frames between two bare python-can processes (``hil bench``'s floor) and between ``hil sim``
and ``hil control --lock-step``, alternately, each split by process and kind of thread.

    python tools/cycle_across_processes.py ur3 --pairs 3

Both runs are placed as ``hil up --lock-step`` places them: every process on one CPU
(:func:`hil.realtime.lock_step_cpus`), where the two take turns and the CPU is never idle.
``perf record`` samples that CPU for a window in the middle of each run; a process' share
of the samples times the run's wall time a cycle is what that process spends a cycle, its
Python threads (the interpreter, and the kernel on their behalf) apart from Zenoh's runtime
threads (``tx-``, ``rx-``, ``net-``, ``acc-``, ``app-``: Rust, the sockets). Needs perf
(Debian: ``apt install linux-perf``) and permission to sample every process of the CPU.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

from hil.bench.floor import floor_across_processes
from hil.bench.processes import stack_across_processes
from hil.bus_config import load_bus_config
from hil.bus_config.locate import config_path
from hil.errors import UsageError
from hil.realtime import LOCK_STEP, lock_step_cpus

#: the names Zenoh's runtime gives its threads
ZENOH_THREADS = ("tx-", "rx-", "net-", "acc-", "app-")
#: before the window: the floor's sessions find each other, the stack enables its drives
SETTLE = 5.0
#: how long each run is sampled (s)
WINDOW = 4.0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("robot", nargs="?", default="ur3",
                        help="a robot's name (ur3, pigot) or a bus config's path (g1.yaml), "
                             "as hil up takes it")
    parser.add_argument("--pairs", type=int, default=1, help="floor and stack, this often")
    args = parser.parse_args()
    if shutil.which("perf") is None:
        parser.error("perf is not installed (Debian: apt install linux-perf)")
    cpus = lock_step_cpus()[0]
    if cpus is None:
        parser.error("one CPU only: lock-step places both processes on it anyway, and the "
                     "window would sample this tool too")
    try:
        config = config_path(args.robot)
    except UsageError as exc:           # its words begin "error:" already
        print(f"{parser.prog}: {exc}", file=sys.stderr)
        return 2
    rows = []
    for _ in range(args.pairs):
        for name, run in (("floor", floor_run), ("stack", stack_run)):
            cycle_us, shares = run(config, min(cpus))
            parts = {" ".join(filter(None, key)): share * cycle_us
                     for key, share in sorted(shares.items())}
            rows.append({"run": name, "cycle_us": cycle_us, "us_a_cycle": parts})
            print(f"{name}: {cycle_us:.0f} us a cycle; " + ", ".join(
                f"{part} {us:.0f} us" for part, us in parts.items()), flush=True)
    print(json.dumps(rows))
    return 0


def floor_run(config_path: Path, cpu: int) -> tuple[float, dict]:
    """The floor, as ``hil bench`` runs it (its answering process is this one's only
    child), sampled mid-run."""
    config = load_bus_config(config_path)
    result, samples, children = _sampled_mid_run(
        lambda seconds: floor_across_processes(config, seconds, paced=False), 1, cpu)
    if "speedup_over_real_time" not in result:
        raise SystemExit("error: the floor did not run")
    cycle_us = 1e6 / (result["speedup_over_real_time"] * config.cycle_hz)
    (responder,) = children
    return cycle_us, _shares(samples, {responder: "sim", os.getpid(): "control"})


def stack_run(config_path: Path, cpu: int) -> tuple[float, dict]:
    """``hil sim`` and ``hil control --lock-step``, as ``hil bench`` runs and places them
    (:func:`hil.bench.processes.stack_across_processes`), sampled mid-run."""
    result, samples, children = _sampled_mid_run(
        lambda seconds: stack_across_processes(config_path, seconds, False, LOCK_STEP), 2, cpu)
    # each child by its role: its hil sub-command (python -m hil ROLE ...)
    roles = {pid: argv[3] for pid, argv in children.items()}
    cycle_us = 1e6 / (result["speedup_over_real_time"] * load_bus_config(config_path).cycle_hz)
    return cycle_us, _shares(samples, roles)


def _sampled_mid_run(run: Callable[[float], dict], children: int, cpu: int
                     ) -> tuple[dict, list[tuple[int, str]], dict[int, list[str]]]:
    """``run(seconds)`` in a thread; once it has started ``children`` child processes and
    they have settled, ``cpu`` sampled for WINDOW: its result, the samples, and each child's
    command line (read while it runs) by its pid."""
    result: dict = {}
    thread = threading.Thread(target=lambda: result.update(run(SETTLE + WINDOW + 2)))
    thread.start()
    started: list[int] = []
    while len(started) < children and thread.is_alive():
        time.sleep(0.1)
        started = _children()
    if len(started) < children:
        thread.join()
        raise SystemExit(f"error: the run ended before its {children} process(es) started")
    argv = {pid: Path(f"/proc/{pid}/cmdline").read_bytes().decode().split("\0")
            for pid in started}
    time.sleep(SETTLE)
    samples = _sampled(cpu)
    thread.join()
    return result, samples, argv


def _children() -> list[int]:
    """This process' child processes, by every thread that may have started one."""
    pids = []
    for task in Path("/proc/self/task").iterdir():
        pids += map(int, (task / "children").read_text().split())
    return pids


def _sampled(cpu: int) -> list[tuple[int, str]]:
    """(pid, thread name) of each perf sample of ``cpu`` over WINDOW seconds."""
    with tempfile.TemporaryDirectory(prefix="hil-perf-") as folder:
        data = Path(folder) / "perf.data"
        subprocess.run(["perf", "record", "-q", "-F", "1999", "-a", "-C", str(cpu), "-o",
                        str(data), "--", "sleep", str(WINDOW)], check=True,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        script = subprocess.run(["perf", "script", "-i", str(data), "-F", "comm,pid"],
                                capture_output=True, text=True, check=True).stdout
    samples = []
    for line in script.splitlines():
        comm, _, pid = line.strip().rpartition(" ")
        if pid.isdigit():
            samples.append((int(pid), comm.strip()))
    return samples


def _shares(samples: list[tuple[int, str]], roles: dict[int, str]) -> dict:
    """Each (role, thread kind)'s share of the samples; others' as ("other", "")."""
    counted: collections.Counter = collections.Counter()
    for pid, comm in samples:
        role = roles.get(pid)
        if role is None:
            counted["other", "idle" if comm == "swapper" else ""] += 1
        else:
            counted[role, "zenoh" if comm.startswith(ZENOH_THREADS) else "python"] += 1
    return {key: count / max(1, len(samples)) for key, count in counted.items()}


if __name__ == "__main__":
    sys.exit(main())
