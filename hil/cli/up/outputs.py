"""What ``hil up`` writes: the rerun recording (whole, or its segments), the CAN log and the
processes' logs; the previous run's, replaced, named before the run begins.

hil's choice, beside what recorders do: rerun's own ``save`` replaces a file silently, ROS
2's ``ros2 bag record`` refuses an existing output folder (its default name carries the
time, so that it never meets one). ``hil up``'s names are fixed (``run.rrd``, which the
README runs again and again), so it replaces them, as rerun does, and says so with each
file's size and time, so that a run worth keeping is not lost without a word: keep one by
moving it, or by giving the next run another ``--save``. A previous run's segments
(``run-0001.rrd``, ...) are removed: ``hil review`` would read them as this run's."""

from __future__ import annotations

import datetime
from pathlib import Path

from hil.visualisation.segments import segment_files


def _described(path: Path) -> str:
    stat = path.stat()
    when = datetime.datetime.fromtimestamp(stat.st_mtime).strftime("%Y-%m-%d %H:%M:%S")
    return f"{path} ({stat.st_size / 1e6:.1f} MB, {when})"


def replace_previous(save: Path, can_log: Path, logs: Path) -> list[str]:
    """The previous run's outputs this run replaces, in words (empty: none); its segments
    removed (see the module doc)."""
    segments = [path for path in segment_files(save) if path != save and path.is_file()]
    found = [_described(path) for path in (save, can_log) if path.is_file()]
    if segments:
        found.append(f"{len(segments)} segment(s) {segments[0].name} ... {segments[-1].name}")
        for path in segments:
            path.unlink()
    if logs.is_dir() and any(logs.iterdir()):
        found.append(f"the process logs in {logs}/")
    return found
