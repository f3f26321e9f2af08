"""The files a command writes (``hil up``'s recording and CAN log, ``hil viz --save`` and
``--can-log``, ``hil replay --record``): each checked before the run begins, and what each
replaces named, for all of them alike.

Checked first, because the writers find out last: rerun's file sink raised a RuntimeError
at the end of a replay for a folder or ``/dev/full`` (whose every write fails with ENOSPC),
after the whole run; a device or a FIFO is no file to keep a run in. So a file to write is
refused, naming it, where it is a folder or no regular file, or where the folder it goes in
cannot take it.

Replaced and said so (hil's choice, beside what recorders do): rerun's own ``save``
replaces a file silently, ROS 2's ``ros2 bag record`` refuses an existing output folder (its
default name carries the time, so that it never meets one). hil's names are often fixed
(``run.rrd``, which the README runs again and again), so hil replaces them, as rerun does,
and says so with each file's size and time, so that a run worth keeping is not lost without
a word. A previous recording's segments (``run-0001.rrd``, ...) are removed: ``hil review``
would read them as the new run's."""

from __future__ import annotations

import datetime
import os
import stat
from pathlib import Path

from hil.errors import UsageError
from hil.visualisation.segments import segment_files


def check_writable(path: Path, what: str) -> None:
    """UsageError naming ``path`` (a ``what``: "--record", ...) where no file can be written
    there: a folder, no regular file (a device such as /dev/full, a FIFO), or in a place
    that is no folder or cannot be written."""
    hint = f"give {what} a file in a folder you can write, e.g. {what} run.rrd"
    try:
        found = os.stat(path)
    except FileNotFoundError:
        found = None
    except OSError as exc:
        raise UsageError.single(f"{what} '{path}': {exc.strerror}", hint=hint) from None
    if found is not None and stat.S_ISDIR(found.st_mode):
        raise UsageError.single(f"{what} '{path}' is a folder", hint=hint)
    if found is not None and not stat.S_ISREG(found.st_mode):
        raise UsageError.single(f"{what} '{path}' is not a regular file (a device, a FIFO): no "
                                "place to keep a run", hint=hint)
    place = Path(path).absolute().parent
    while not place.exists():                 # the folders to be made: the first that is
        place = place.parent
    if not place.is_dir():
        raise UsageError.single(f"{what} '{path}': '{place}' is not a folder", hint=hint)
    # os.access: as the process may, read-only file systems included (EROFS)
    if not os.access(place, os.W_OK | os.X_OK) or (
            found is not None and not os.access(path, os.W_OK)):
        raise UsageError.single(f"{what} '{path}': cannot write in '{place}'", hint=hint)


def described(path: Path) -> str:
    """A file in words: its path, size and time of its last change."""
    found = path.stat()
    when = datetime.datetime.fromtimestamp(found.st_mtime).strftime("%Y-%m-%d %H:%M:%S")
    return f"{path} ({found.st_size / 1e6:.1f} MB, {when})"


def previous_outputs(outputs: dict[str, Path], recording: Path | None = None) -> list[str]:
    """Every output (option -> file) checked (:func:`check_writable`) and its folder made;
    then what they replace, in words (empty: nothing). ``recording``: the one of them that
    is a rerun recording, whose previous segments are removed (the module doc)."""
    for option, path in outputs.items():
        check_writable(path, option)
    for path in outputs.values():
        path.absolute().parent.mkdir(parents=True, exist_ok=True)
    found = [described(path) for path in outputs.values() if path.is_file()]
    segments = [path for path in segment_files(recording)
                if path != recording and path.is_file()] if recording is not None else []
    if segments:
        found.append(f"{len(segments)} segment(s) {segments[0].name} ... {segments[-1].name}")
    for path in segments:
        path.unlink()
    return found
