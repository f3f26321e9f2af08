"""CPU instructions per lock-step cycle of the in-process stack, counted by valgrind's
callgrind (a benchmark, not a test): for before/after comparisons on a shared host, where a
cycle's wall time moves by tens of percent with the neighbours and an instruction count
does not.

    python tools/cycle_instructions.py ur3 pigot
    python tools/cycle_instructions.py ur3 --root /tmp/base --root .    # two checkouts
    python tools/cycle_instructions.py g1.yaml --cycles 500             # a bus config

Each count is two runs of the stack (``hil.stack.running_stack``, lock-step) under
``valgrind --tool=callgrind --separate-threads=yes``: one of WARM_UP cycles and one of
WARM_UP + CYCLES; per cycle is the difference of the control thread's instructions over the
difference of the cycles the node ran. In one process the control thread carries the whole
cycle: the master's frames, the drives' handling and the plant's steps happen in its
delivery (the virtual bus delivers in the sender's thread). The thread is the one, other
than the main thread, that steps MuJoCo. Bring-up and shutdown are the same in both runs
and cancel. Needs valgrind (Debian: ``apt install valgrind``); a run takes minutes.
``--root`` runs the hil of another checkout (its compiled drive core, if any, built there),
so that two commits are counted in one sitting, alternately.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

#: cycles of the shorter run, and the default more of the longer one
WARM_UP = 200
CYCLES = 2000
#: the child: a lock-step stack run for N cycles; prints the cycles the node ran in all
CHILD = """
import sys, time
from pathlib import Path
from hil.bench.settings import BenchSettings
from hil.bus_config import load_bus_config
from hil.realtime.timing import LOCK_STEP
from hil.stack import running_stack
robot = Path(sys.argv[1])
config = load_bus_config(robot if robot.suffix == ".yaml" else
                         BenchSettings.quick().config_dir / (sys.argv[1] + ".yaml"))
with running_stack(config, LOCK_STEP) as stack:
    while stack.node.cycles < int(sys.argv[2]):
        time.sleep(0.01)
print(stack.node.cycles)
"""
SUMMARY = re.compile(rb"^summary: (\d+)", re.MULTILINE)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("robots", nargs="+", metavar="ROBOT",
                        help="a seed robot (ur3, pigot) or a bus config file (.yaml)")
    parser.add_argument("--cycles", type=int, default=CYCLES)
    parser.add_argument("--root", action="append", type=Path, default=[],
                        help="a checkout whose hil to count (default: the installed one; "
                             "repeat to count several, alternately)")
    parser.add_argument("--pairs", type=int, default=1, help="repeat each count this often")
    args = parser.parse_args()
    # a config file from here, whichever checkout's folder a run starts in
    args.robots = [str(Path(robot).resolve()) if robot.endswith(".yaml") else robot
                   for robot in args.robots]
    if shutil.which("valgrind") is None:
        parser.error("valgrind is not installed (Debian: apt install valgrind)")
    rows = []
    for _ in range(args.pairs):
        for robot in args.robots:
            for root in args.root or [None]:
                per_cycle = instructions_per_cycle(robot, args.cycles, root)
                rows.append({"robot": robot, "root": str(root or "installed"),
                             "instructions_per_cycle": per_cycle})
                print(f"{robot:8} {rows[-1]['root']:30} {per_cycle / 1e3:9.1f} k instructions "
                      "a cycle", flush=True)
    print(json.dumps(rows))
    return 0


def instructions_per_cycle(robot: str, cycles: int, root: Path | None) -> float:
    """The control thread's instructions per lock-step cycle (see the module doc)."""
    short, long = (_counted_run(robot, n, root) for n in (WARM_UP, WARM_UP + cycles))
    return (long[1] - short[1]) / (long[0] - short[0])


def _counted_run(robot: str, cycles: int, root: Path | None) -> tuple[int, int]:
    """(cycles the node ran, instructions of its control thread) of one run."""
    env = dict(os.environ)
    if root is not None:
        env["PYTHONPATH"] = str(root.resolve())
    with tempfile.TemporaryDirectory(prefix="hil-callgrind-") as folder:
        out = Path(folder) / "callgrind.out"
        done = subprocess.run(
            ["valgrind", "--tool=callgrind", "--separate-threads=yes",
             f"--callgrind-out-file={out}", sys.executable, "-c", CHILD, robot, str(cycles)],
            env=env, cwd=root, capture_output=True)
        if done.returncode != 0:
            said = [line for line in done.stderr.decode(errors="replace").splitlines()
                    if line.strip() and not line.startswith("==")][-5:]    # not valgrind's
            raise SystemExit(f"error: the stack of '{robot}' ({root or 'installed hil'}) "
                             f"did not run under valgrind:\n  " + "\n  ".join(said))
        ran = int(done.stdout.split()[-1])
        # one file a thread: <out>-01 is the main thread (it builds the model and steps it
        # once); the control thread is the other one that steps MuJoCo
        threads = [f.read_bytes() for f in sorted(Path(folder).glob("callgrind.out-*"))
                   if not f.name.endswith("-01")]
        counts = [int(SUMMARY.search(text).group(1)) for text in threads if b"mj_step" in text]
    if len(counts) != 1:
        raise RuntimeError(f"expected one thread besides the main one to step MuJoCo, "
                           f"found {len(counts)}")
    return ran, counts[0]


if __name__ == "__main__":
    sys.exit(main())
