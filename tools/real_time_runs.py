"""Repeated real-time runs of ``hil up`` and their verdicts (a benchmark, not a test: issue
28's bound "every run fault-free or every fault attributed to a measured stall").

    python tools/real_time_runs.py ur3 pigot --runs 10 --seconds 60 --folder runs/
    python tools/real_time_runs.py --scale 12@500 --scale 34@250 --runs 10 --folder runs/

Each run is ``hil up TARGET --real-time --duration S --no-viewer`` (the visualiser
recording, as a user runs it), the robots alternating run by run. ``--scale N@HZ`` runs the
robot ``hil bench``'s scale section makes (N joints of ur3 arms on one base, the buses
``hil init`` gives them at HZ). A run is told by ``hil up``'s exit status alone: 0 clean,
3 every fault explained by a stall of the bench (a flaky host), 1 a fault no stall
explains. The controller's summary line and ``hil up``'s line of the bench's stalls are
kept beside each run. Prints a line per run and a tally per target, and writes every run
to ``FOLDER/runs.json``.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

from hil.bench.scale import scale_bench

HIL = [sys.executable, "-m", "hil"]
#: hil up's exit status, in words (hil up --help)
VERDICTS = {0: "clean", 3: "bench fault", 1: "unexplained"}
#: the controller's closing line (hil.control_node): cycles, missed, busy and round trip
SUMMARY = re.compile(r"(\d+) cycles, missed (\d+);.*busy p50 (\d+) us, p99 (\d+) us;.*"
                     r"round trip p50 (\d+) us, p99 (\d+) us")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("targets", nargs="*", metavar="ROBOT|CONFIG")
    parser.add_argument("--scale", action="append", default=[], metavar="N@HZ",
                        help="also run the scale section's robot of N drives at HZ")
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--seconds", type=float, default=60.0)
    parser.add_argument("--folder", type=Path, default=Path("runs"))
    args = parser.parse_args()
    args.folder.mkdir(parents=True, exist_ok=True)
    targets = list(args.targets)
    for size in args.scale:
        drives, _, rate = size.partition("@")
        targets.append(str(_scale_config(int(drives), float(rate or 500), args.folder)))
    if not targets:
        parser.error("name a robot or config, or --scale N@HZ")
    runs = []
    for index in range(args.runs):
        for target in targets:
            runs.append(_run(target, index + 1, args.seconds, args.folder))
            print(_row(runs[-1]), flush=True)
            (args.folder / "runs.json").write_text(json.dumps(runs, indent=1))
    print()
    for target in targets:
        print(_tally([run for run in runs if run["target"] == Path(target).stem]))
    return 0


def _scale_config(drives: int, rate: float, folder: Path) -> Path:
    config, buses = scale_bench(drives, rate, folder)
    print(f"{config}: {drives} drives on {buses} buses at {rate:g} Hz", flush=True)
    return config


def _run(target: str, index: int, seconds: float, folder: Path) -> dict:
    name = Path(target).stem
    where = folder / f"{name}-{index:02d}"
    where.mkdir(parents=True, exist_ok=True)
    started = time.monotonic()
    with (where / "up.log").open("w") as log:
        robot = str(Path(target).resolve()) if Path(target).exists() else target
        status = subprocess.run([*HIL, "up", robot, "--real-time", "--duration", f"{seconds:g}",
                                 "--no-viewer"], stdout=log, stderr=subprocess.STDOUT,
                                cwd=where).returncode
    control = where / "run.logs" / "control.log"
    lines = control.read_text().splitlines() if control.exists() else []
    match = next(filter(None, map(SUMMARY.search, lines)), None)
    faults = [line for line in lines if "fault" in line.lower() or "silent" in line]
    stalls = next((line for line in (where / "up.log").read_text().splitlines()
                   if line.startswith("hil up: the bench's")), "")
    run = {"target": name, "run": index, "status": status,
           "verdict": VERDICTS.get(status, f"failed (exit {status})"),
           "wall_s": round(time.monotonic() - started, 1),
           "summary": match.string if match else "", "stalls": stalls, "faults": faults[:8]}
    if match:
        run.update(zip(("cycles", "missed", "busy_p50_us", "busy_p99_us", "round_trip_p50_us",
                        "round_trip_p99_us"), map(int, match.groups())))
    return run


def _row(run: dict) -> str:
    figures = (f"cycles {run['cycles']}, missed {run['missed']}, busy p99 "
               f"{run['busy_p99_us']} us, round trip p50/p99 {run['round_trip_p50_us']}/"
               f"{run['round_trip_p99_us']} us" if "cycles" in run else "no controller summary")
    return f"{run['target']:>14} #{run['run']:02d}  {run['verdict']:<12} {figures}"


def _tally(runs: list[dict]) -> str:
    counted = Counter(run["verdict"] for run in runs)
    counts = {verdict: counted[verdict] for verdict in dict.fromkeys([*VERDICTS.values(),
                                                                      *counted])}
    missed = [run["missed"] for run in runs if "missed" in run]
    spread = f"; missed {min(missed)}-{max(missed)} of each run's cycles" if missed else ""
    return (f"{runs[0]['target']}: {len(runs)} runs: "
            + ", ".join(f"{count} {verdict}" for verdict, count in counts.items()) + spread)


if __name__ == "__main__":
    sys.exit(main())
