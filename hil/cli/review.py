"""``hil review FILE.rrd``: a recorded run opened for review: its segments (``FILE-0001.rrd``
and on, as ``--segment`` wrote them, or the one file), a summary per robot (cycles, duration,
each joint's tracking error, the loop's period), every fault and reset with its time, then
rerun's viewer on them all (one recording: the segments join on its timelines), its
"diagnostics" view one click from each fault; ``--json`` for CI, ``--web`` for a browser."""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

from hil.cli import common
from hil.errors import UsageError
from hil.supervisor import run_foreground
from hil.visualisation.review import RunSummary, review
from hil.visualisation.segments import segment_files


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("recording", type=Path,
                        help="the .rrd of hil up or hil viz --save (its segments FILE-0001.rrd, "
                             "... beside it are found by that name)")
    shown = parser.add_mutually_exclusive_group()
    shown.add_argument("--no-viewer", action="store_true",
                       help="print what the recording holds; open no viewer")
    shown.add_argument("--json", action="store_true",
                       help="print what the recording holds as one JSON document (for CI); "
                            "open no viewer")
    shown.add_argument("--web", action="store_true",
                       help="serve rerun's web viewer with the recording on this host's "
                            "loopback and print its address (for a host without a display: "
                            "forward the port, e.g. ssh -L 9090:localhost:9090); until Ctrl-C. "
                            "The browser needs WebGL (a software rasteriser will do) and some "
                            "30 s to show the run: a headless screenshot taken at once shows "
                            "'Loading'")
    parser.add_argument("--web-port", type=int, default=9090, metavar="PORT",
                        help="the web viewer's HTTP port (default 9090; its data on PORT+1)")


def run(args: argparse.Namespace) -> int:
    files = segment_files(args.recording)
    if files == [args.recording] and not args.recording.exists():
        raise UsageError.single(f"no recording {args.recording} (nor its segments "
                                f"{args.recording.stem}-0001{args.recording.suffix}, ...)",
                                hint="give the --save of hil up or hil viz (default run.rrd)")
    reviewed = review(files)
    unreadable = {damage.segment for damage in reviewed.damaged if not damage.is_recording}
    viewable = [path for path in files if path not in unreadable]
    if args.json:
        print(json.dumps(_document(args.recording, files, reviewed), indent=1))
        return 0 if viewable else 1
    size = sum(path.stat().st_size for path in files)
    print(f"hil review: {args.recording}: {len(files)} file(s), {size / 1e6:.1f} MB"
          + (f" ({files[0].name} ... {files[-1].name})" if len(files) > 1 else ""))
    for damage in reviewed.damaged:
        print(f"hil review: {damage.segment.name} damaged: {damage.reason}")
    if not viewable:
        raise UsageError.single(f"{args.recording}: no file of it is a rerun recording",
                                hint="give the --save of hil up or hil viz (default run.rrd)")
    for run in reviewed.runs:
        _print_run(run)
    found = reviewed.diagnostics
    faults = [d for d in found if d.level == "ERROR"]
    print(f"hil review: {len(faults)} fault(s), {len(found) - len(faults)} other diagnostic(s)")
    for diagnostic in found:
        clock = (f", control {diagnostic.control_time:.3f} s"
                 if diagnostic.control_time is not None else "")
        print(f"  {diagnostic.wall_time:%Y-%m-%d %H:%M:%S.%f}{clock}  {diagnostic.level:<5} "
              f"{diagnostic.text}  [{diagnostic.segment.name}]")
    if args.web:
        return _serve_web(viewable, args.web_port)
    if args.no_viewer:
        return 0
    if not common.display_available():
        print(f"hil review: no display here; on one: rerun {' '.join(map(str, viewable))}; "
              f"or in a browser: hil review {args.recording} --web")
        return 0
    print("hil review: in the viewer, the 'diagnostics' view lists them: a click puts the "
          "timelines at one", flush=True)
    return run_foreground([_rerun(), *map(str, viewable)])


def _print_run(run: RunSummary) -> None:
    period = (f"; loop period mean {run.period_mean_ms:.3f} ms, max {run.period_max_ms:.3f} ms"
              if run.period_mean_ms is not None else "; no loop period (lock-step)")
    # one time base: the controller's clock, as the largest errors' times, the diagnostics'
    # and the viewer's control_time timeline give it (it began before the first recorded
    # cycle: the controller's bring-up, or a recorder that joined later)
    print(f"hil review: {run.robot or 'the run'}: {run.cycles} cycles over "
          f"{run.duration:.3f} s of control time, {run.first:.3f} s to {run.last:.3f} s"
          f"{period}")
    print(f"  {'joint':24s} {'error rms':>12s} {'error max':>12s}  at control time")
    for joint in run.joints.values():
        at = f"{joint.max_at:.3f} s" if joint.max_at is not None else "-"
        print(f"  {joint.joint:24s} {joint.rms:12.3g} {joint.max:12.3g}  {at}  [{joint.unit}]")
    stalls = ", ".join(f"{process} {count} (longest {longest:.1f} ms)"
                       for process, (count, longest) in sorted(run.stalls.items()))
    print(f"  stalls: {stalls or 'none recorded'}")


def _document(recording: Path, files: list[Path], reviewed) -> dict:
    """``--json``: everything the text says, as data."""
    return {
        "recording": str(recording), "files": [str(path) for path in files],
        "damaged": [{"file": str(d.segment), "reason": d.reason} for d in reviewed.damaged],
        "runs": [{"robot": run.robot, "cycles": run.cycles, "duration_s": run.duration,
                  "first_control_time_s": run.first, "last_control_time_s": run.last,
                  "period_mean_ms": run.period_mean_ms, "period_max_ms": run.period_max_ms,
                  "stalls": {process: {"count": count, "longest_ms": longest}
                             for process, (count, longest) in run.stalls.items()},
                  "joints": {j.joint: {"unit": j.unit, "rms": j.rms, "max": j.max,
                                       "max_at_control_time_s": j.max_at}
                             for j in run.joints.values()}} for run in reviewed.runs],
        "faults": sum(d.level == "ERROR" for d in reviewed.diagnostics),
        "diagnostics": [{"wall_time": d.wall_time.isoformat(), "control_time_s": d.control_time,
                         "level": d.level, "text": d.text, "file": str(d.segment)}
                        for d in reviewed.diagnostics],
    }


def _serve_web(files: list[Path], port: int) -> int:
    """rerun's web viewer over HTTP on loopback, the recording from its own data server
    beside it (rerun's ``--serve-web``), until Ctrl-C."""
    command = [_rerun(), "--serve-web", "--bind", "127.0.0.1", "--web-viewer-port", str(port),
               "--port", str(port + 1), *map(str, files)]
    print(f"hil review: web viewer at http://127.0.0.1:{port}/?url=rerun%2Bhttp://127.0.0.1:"
          f"{port + 1}/proxy (Ctrl-C ends it)", flush=True)
    # measured (2026-12-06, headless Chromium 156 on this project's 2-CPU host): `chromium
    # --headless --screenshot URL` shot a blank page, with --virtual-time-budget "Loading
    # Application Bundle": it shoots at the page's load, before the viewer's wasm has
    # compiled and streamed the recording (real time, which virtual time does not wait
    # for); through DevTools, 35 s after navigating, the whole run showed (tools/
    # web_screenshot.py), on SwiftShader's WebGL ("Software rasterizer")
    print("hil review: a browser needs WebGL (a software rasteriser will do) and some 30 s to "
          "load the viewer and the recording; a headless `chromium --screenshot` shoots at "
          "once and catches \"Loading\": wait before the screenshot (DevTools, as hil's "
          "tools/web_screenshot.py does)", flush=True)
    return run_foreground(command)


def _rerun() -> str:
    """rerun's command line program: on PATH, else beside this Python (a venv's)."""
    return shutil.which("rerun") or str(Path(sys.executable).with_name("rerun"))
