"""What a real-time run's recording costs on a loaded host (a benchmark, not a test).

    python tools/recording_under_load.py --seconds 30 --busy 2

Runs ``hil up ROBOT --real-time --duration SECONDS`` with ``--busy`` processes spinning
beside it (each a Python loop at full speed, for the run's length), then prints the
recording's size per second of run, the stalls the run saw, and what ``rerun rrd verify``
says of the file. Issue 47's bound: at most 0.15 MB/s with a second busy process.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
from pathlib import Path

HIL = [sys.executable, "-m", "hil"]
SPIN = [sys.executable, "-c", "while True: pass"]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="pigot")
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--busy", type=int, default=1, help="busy processes beside the run")
    args = parser.parse_args()
    spinners = [subprocess.Popen(SPIN) for _ in range(args.busy)]
    try:
        with tempfile.TemporaryDirectory() as folder:
            save = Path(folder) / "run.rrd"
            run = subprocess.run([*HIL, "up", args.robot, "--real-time", "--duration",
                                  f"{args.seconds:g}", "--no-viewer", "--save", str(save)],
                                 capture_output=True, text=True, cwd=folder)
            if run.returncode != 0:
                print(run.stdout + run.stderr)
                return run.returncode
            recorded = re.search(r"recorded .*", run.stdout)
            verify = subprocess.run([str(Path(sys.executable).with_name("rerun")), "rrd",
                                     "verify", str(save)], capture_output=True, text=True)
            size = save.stat().st_size
    finally:
        for spinner in spinners:
            spinner.kill()
            spinner.wait()
    print(f"{args.robot}, {args.seconds:g} s real time, {args.busy} busy process(es): "
          f"{size / 1e6:.2f} MB, {size / args.seconds / 1e6:.3f} MB/s; "
          f"{recorded.group(0) if recorded else 'no recording summary'}; rrd verify: "
          f"{'passed' if verify.returncode == 0 else verify.stderr.strip()[-300:]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
