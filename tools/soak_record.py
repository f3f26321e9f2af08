"""A soak of the recording: ``hil up ROBOT`` in real time for a long time with the
visualiser recording every cycle, watched from outside every minute (a benchmark, not a
test: what memory, the recording's lag and the files do over an hour).

    python tools/soak_record.py --robot ur3 --seconds 3600 --folder soak/

Every ``--every`` seconds it reads each process' resident memory from /proc (hil up, and
its sim, control and viz), the recording's files (every segment) and the CAN log, and the
visualiser's own status line of that minute from ``viz.log`` (cycles recorded, cycles lost,
its lag's p99 over the minute). At the end it prints the table and the verdict of issue 32's
bound (RSS growth after the first 5 minutes under 10 %, the largest later sample against
the one at 5 minutes; lag p99 under 1 s, nothing lost)
and writes every sample to ``FOLDER/soak.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

HIL = [sys.executable, "-m", "hil"]
#: the visualiser's status line (hil.visualisation.node): cycles, lost, lag p99
STATUS = re.compile(r"hil viz: \[\s*(\d+) s\] (\d+) cycles, (\d+) lost; (\d+) batches"
                    r"(?:; lag p50 ([0-9.]+) ms, p99 ([0-9.]+) ms)?")
#: after this long (s) memory should no longer grow
WARM = 300.0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="ur3")
    parser.add_argument("--seconds", type=float, default=3600.0)
    parser.add_argument("--every", type=float, default=60.0)
    parser.add_argument("--segment", default="10m", help="hil up --segment (default 10m)")
    parser.add_argument("--folder", type=Path, default=Path("soak"))
    args = parser.parse_args()
    args.folder.mkdir(parents=True, exist_ok=True)
    save = args.folder / "run.rrd"
    up = subprocess.Popen([*HIL, "up", args.robot, "--real-time", "--duration",
                           f"{args.seconds:g}", "--no-viewer", "--save", str(save),
                           "--segment", args.segment],
                          stdout=(args.folder / "up.log").open("w"), stderr=subprocess.STDOUT,
                          cwd=args.folder)
    samples = []
    started = time.monotonic()
    try:
        while up.poll() is None:
            time.sleep(max(0.0, started + (len(samples) + 1) * args.every - time.monotonic()))
            if up.poll() is not None:
                break
            samples.append(_sample(up.pid, args.folder, time.monotonic() - started))
            print(_row(samples[-1]), flush=True)
    except KeyboardInterrupt:
        up.send_signal(signal.SIGINT)
    status = up.wait()
    report = {"robot": args.robot, "seconds": args.seconds, "exit_status": status,
              "samples": samples, "verdict": _verdict(samples)}
    (args.folder / "soak.json").write_text(json.dumps(report, indent=2))
    print(json.dumps(report["verdict"], indent=2))
    return 0 if status == 0 else status


def _sample(up_pid: int, folder: Path, elapsed: float) -> dict:
    processes = {"up": up_pid, **_children(up_pid)}
    rss = {name: _rss_mb(pid) for name, pid in processes.items()}
    rrd = sum(path.stat().st_size for path in folder.glob("run*.rrd")) / 1e6
    can = sum(path.stat().st_size for path in folder.glob("run.can.*")) / 1e6
    viz = _last_status(folder / "run.logs" / "viz.log")
    return {"seconds": round(elapsed), "rss_mb": rss, "rrd_mb": round(rrd, 1),
            "can_log_mb": round(can, 1), **viz}


def _children(pid: int) -> dict[str, int]:
    """hil up's children by their sub-command (sim, control, viz)."""
    found = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            command = (entry / "cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        parent = int(stat.rpartition(")")[2].split()[1])
        words = [part.decode(errors="replace") for part in command]
        if parent == pid and "hil" in words:
            found[words[words.index("hil") + 1]] = int(entry.name)
    return found


def _rss_mb(pid: int) -> float | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return round(int(line.split()[1]) / 1024, 1)
    except OSError:
        return None
    return None


def _last_status(log: Path) -> dict:
    try:
        lines = [m for m in map(STATUS.search, log.read_text().splitlines()) if m]
    except OSError:
        return {}
    if not lines:
        return {}
    last = lines[-1]
    return {"cycles": int(last.group(2)), "lost": int(last.group(3)),
            "lag_p99_ms": float(last.group(6)) if last.group(6) else None}


def _row(sample: dict) -> str:
    rss = " ".join(f"{name} {mb} MB" for name, mb in sample["rss_mb"].items())
    return (f"[{sample['seconds']:6d} s] {rss}; rrd {sample['rrd_mb']} MB, CAN log "
            f"{sample['can_log_mb']} MB; cycles {sample.get('cycles')}, lost "
            f"{sample.get('lost')}, lag p99 {sample.get('lag_p99_ms')} ms")


def _verdict(samples: list[dict]) -> dict:
    warm = [s for s in samples if s["seconds"] >= WARM]
    growth = {}
    if len(warm) >= 2:           # the largest after warm-up, not the last: memory may saw
        for name in warm[0]["rss_mb"]:           # (a segment's index is freed as it closes)
            first = warm[0]["rss_mb"].get(name)
            later = [s["rss_mb"][name] for s in warm[1:] if s["rss_mb"].get(name)]
            if first and later:
                growth[name] = round(100 * (max(later) - first) / first, 1)
    lags = [s["lag_p99_ms"] for s in samples if s.get("lag_p99_ms") is not None]
    return {"rss_growth_after_5_min_percent": growth,
            "lag_p99_ms_worst_minute": max(lags) if lags else None,
            "cycles_lost": samples[-1].get("lost") if samples else None,
            "rrd_mb_per_hour": (round(samples[-1]["rrd_mb"] * 3600 / samples[-1]["seconds"])
                                if samples else None)}


if __name__ == "__main__":
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    sys.exit(main())
