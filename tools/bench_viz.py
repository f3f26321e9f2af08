#!/usr/bin/env python3
"""Can `hil viz` keep up with a 1 kHz controller of 7 joints? Measure it.

Publishes synthetic control samples for the pigot (7 driven joints, 7 drives)
at RATE cycles per second, in batches of RATE/10 as `hil control` does, over
Zenoh on loopback to a `hil viz` process that records to a temporary .rrd.
Reports cycles published vs logged, the viz's lag (logged time minus newest
sample time, per batch), its logging time per batch, and its CPU use.

    .venv/bin/python tools/bench_viz.py [--rate 1000] [--seconds 20] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import re
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from hil.bench.floor import cpu_seconds                              # noqa: E402
from hil.bus_config import load_bus_config                          # noqa: E402
from hil.hardware import JointFeedback                              # noqa: E402
from hil.messaging.samples import ControlSampleBuffer                # noqa: E402
from hil.messaging.zenoh_api import ControlSamplesPublisher, ProcessWatch  # noqa: E402
from hil.zenoh_session import (                                    # noqa: E402
    ZenohSettings, close_all, free_loopback_port, session,
)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rate", type=float, default=1000.0, help="control cycles per second")
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--json", type=Path, help="also write the figures here")
    args = parser.parse_args()

    config = load_bus_config(ROOT / "bus_config" / "pigot.yaml")
    joints = [j.name for j in config.robot.driven_joints]
    actuators = [a.name for a in config.robot.actuators]
    endpoint = f"tcp/127.0.0.1:{free_loopback_port()}"
    zenoh = session(ZenohSettings(listen=(endpoint,)))
    publisher = ControlSamplesPublisher(zenoh, "pigot")
    watch = ProcessWatch(zenoh, "pigot")
    folder = tempfile.mkdtemp(prefix="hil-bench-viz-")
    viz = subprocess.Popen([sys.executable, "-m", "hil", "viz", str(ROOT / "bus_config/pigot.yaml"),
                            "--no-can", "--connect", endpoint, "--save", f"{folder}/run.rrd"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    if not watch.wait_alive("viz", 60):
        viz.kill()
        print(viz.communicate()[1], file=sys.stderr)
        return 1
    batch = max(1, round(args.rate / 10))
    buffer = ControlSampleBuffer(joints, actuators, 1 / args.rate, batch)
    states = ("OPERATION ENABLED",) * len(actuators)
    cpu_start, started = cpu_seconds(viz.pid), time.perf_counter()
    cycles = 0
    while cycles < args.seconds * args.rate:
        cycles += 1
        t = cycles / args.rate
        q = np.sin(t + np.arange(len(joints)))
        buffer.add(cycles, t, q, q, JointFeedback(q, q, q, q, states))
        if buffer.full:
            publisher.publish(buffer.take())
        delay = started + cycles / args.rate - time.perf_counter()
        if delay > 0:
            time.sleep(delay)
    wall = time.perf_counter() - started
    time.sleep(1.0)
    cpu = cpu_seconds(viz.pid) - cpu_start
    viz.send_signal(signal.SIGTERM)
    out, err = viz.communicate(timeout=60)
    publisher.close()
    watch.close()
    close_all()
    summary = re.search(r"(\d+) cycles in (\d+) batches, (\d+) lost; lag p50 ([\d.]+) ms, p99 "
                        r"([\d.]+) ms, max ([\d.]+) ms; logging ([\d.]+) ms per batch", out)
    if not summary:
        print(out + err, file=sys.stderr)
        return 1
    logged, batches, lost, p50, p99, worst, logging = summary.groups()
    figures = {
        "rate_hz": args.rate, "joints": len(joints), "seconds": round(wall, 2),
        "cycles_published": cycles, "cycles_logged": int(logged), "cycles_lost": int(lost),
        "batches": int(batches), "lag_ms": {"p50": float(p50), "p99": float(p99),
                                            "max": float(worst)},
        "logging_ms_per_batch": float(logging),
        "viz_cpu_fraction": round(cpu / (wall + 1.0), 3),
        "rrd_bytes": Path(folder, "run.rrd").stat().st_size,
    }
    print(f"hil viz at {args.rate:g} Hz x {len(joints)} joints for {wall:.1f} s: "
          f"{logged}/{cycles} cycles logged ({lost} lost), lag p50 {p50} ms, p99 {p99} ms, "
          f"max {worst} ms (batches every {batch / args.rate * 1e3:g} ms), logging {logging} ms "
          f"per batch, viz CPU {100 * figures['viz_cpu_fraction']:.0f} % of one core")
    if args.json:
        args.json.write_text(json.dumps(figures, indent=2))
    return 0 if int(logged) == cycles else 1



if __name__ == "__main__":
    sys.exit(main())
