"""``hil review FILE.rrd``: a recorded run opened for review: its segments (``FILE-0001.rrd``
and on, as ``--segment`` wrote them, or the one file), every fault and reset with its time,
then rerun's viewer on them all (one recording: the segments join on its timelines), its
"diagnostics" view one click from each fault."""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
from pathlib import Path

from hil.cli import common
from hil.errors import HilError
from hil.visualisation.review import review
from hil.visualisation.segments import segment_files


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("recording", type=Path,
                        help="the .rrd of hil up or hil viz --save (its segments FILE-0001.rrd, "
                             "... beside it are found by that name)")
    parser.add_argument("--no-viewer", action="store_true",
                        help="print what the recording holds; open no viewer")


def run(args: argparse.Namespace) -> int:
    files = [path for path in segment_files(args.recording) if path.is_file()]
    if not files:
        raise HilError.single(f"no recording {args.recording} (nor its segments "
                              f"{args.recording.stem}-0001{args.recording.suffix}, ...)",
                              hint="give the --save of hil up or hil viz (default run.rrd)")
    size = sum(path.stat().st_size for path in files)
    print(f"hil review: {args.recording}: {len(files)} file(s), {size / 1e6:.1f} MB"
          + (f" ({files[0].name} ... {files[-1].name})" if len(files) > 1 else ""))
    reviewed = review(files)
    for damage in reviewed.damaged:
        print(f"hil review: {damage.segment.name} damaged: {damage.reason}")
    unreadable = {damage.segment for damage in reviewed.damaged if not damage.is_recording}
    viewable = [path for path in files if path not in unreadable]
    if not viewable:
        raise HilError.single(f"{args.recording}: no file of it is a rerun recording",
                              hint="give the --save of hil up or hil viz (default run.rrd)")
    found = reviewed.diagnostics
    faults = [d for d in found if d.level == "ERROR"]
    print(f"hil review: {len(faults)} fault(s), {len(found) - len(faults)} other diagnostic(s)")
    for diagnostic in found:
        clock = (f", control {diagnostic.control_time:.3f} s"
                 if diagnostic.control_time is not None else "")
        print(f"  {diagnostic.wall_time:%Y-%m-%d %H:%M:%S.%f}{clock}  {diagnostic.level:<5} "
              f"{diagnostic.text}  [{diagnostic.segment.name}]")
    if args.no_viewer:
        return 0
    if not common.display_available():
        print(f"hil review: no display here; on one: rerun {' '.join(map(str, viewable))}")
        return 0
    viewer = shutil.which("rerun") or str(Path(sys.executable).with_name("rerun"))
    print("hil review: in the viewer, the 'diagnostics' view lists them: a click puts the "
          "timelines at one", flush=True)
    return subprocess.call([viewer, *map(str, viewable)])
