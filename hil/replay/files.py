"""A CAN log's files as a replay reads them: one file in any format python-can's
``LogReader`` opens, or a folder of a log per bus, each named after its bus (``arm.blf``: what
:meth:`hil.testing.DrivesBench.log_to` and the ``hil_drives`` fixture write), read as one
log in time order (the module doc of :mod:`hil.replay.log`); and whether a log is whole."""

from __future__ import annotations

import heapq
import struct
import zlib
from collections.abc import Iterator
from pathlib import Path

import can
from can.io.blf import BLFParseError

from hil.errors import HilError

#: the files of a folder of logs a replay reads (python-can's LogReader's formats)
LOG_SUFFIXES = (".blf", ".asc", ".log", ".csv", ".trc", ".mf4")


#: what python-can's readers raise on a damaged file (BLF: a bad header or object, a
#: container whose zlib stream is corrupt)
_DAMAGED = (ValueError, OSError, EOFError, struct.error, BLFParseError, zlib.error)


def log_files(path: Path) -> list[Path]:
    """The files of a log: ``path``, or a folder's logs (one per bus, named after it)."""
    if not path.is_dir():
        return [path]
    found = sorted(f for f in path.iterdir() if f.suffix.lower() in LOG_SUFFIXES)
    if not found:
        raise HilError.single(f"{path} is a folder with no CAN log in it",
                              hint="give a log file, or a folder of a log per bus named after "
                                   f"it ({', '.join(f'BUS{s}' for s in LOG_SUFFIXES)})")
    return found


def read_log(path: Path) -> Iterator[can.Message]:
    """The frames of a log (a clear error where python-can cannot read it); of a folder's
    logs, merged by time, each frame's channel the name of its file (its bus')."""
    files = log_files(path)
    if files == [path]:
        yield from _read_file(path)
        return

    def named(file: Path) -> Iterator[can.Message]:
        for msg in _read_file(file):
            msg.channel = file.stem
            yield msg
    yield from heapq.merge(*map(named, files), key=lambda msg: msg.timestamp)


def _read_file(path: Path) -> Iterator[can.Message]:
    try:
        reader = can.LogReader(str(path))
    except (*_DAMAGED, ImportError) as exc:
        raise HilError.single(f"cannot read CAN log '{path}': {exc}",
                              hint="give a .blf, .asc, .log (candump), .csv, .trc or .mf4 "
                                   "file, or a folder of them, one per bus named after it") \
            from None
    try:
        yield from reader
    except _DAMAGED as exc:
        raise HilError.single(f"CAN log '{path}' is damaged: {exc}",
                              hint="a log cut off mid-frame replays up to there only if its "
                                   "format allows: cut it at a whole frame") from None
    finally:
        reader.stop()


def not_whole(path: Path) -> str | None:
    """Why a log (or a folder's logs) is not whole, where its format can tell (a BLF's header
    gives the file's size, written when the log is closed): None where it is whole or its
    format cannot say. python-can reads such a log up to its last whole frame without a
    word."""
    cut = [(file, why) for file in log_files(path) if (why := _file_not_whole(file))]
    if not cut:
        return None
    if cut[0][0] == path:
        return cut[0][1]
    return "; ".join(f"{file.name}: {why}" for file, why in cut)


def _file_not_whole(path: Path) -> str | None:
    if path.suffix.lower() != ".blf":
        return None
    try:
        reader = can.BLFReader(str(path))
    except _DAMAGED:
        return None                           # read_log names what is wrong with it
    said, size = reader.file_size, path.stat().st_size
    reader.stop()
    if said == size:
        return None
    return (f"its header gives {said} bytes and it has {size}: cut off, or never closed (a "
            "crash?); replayed up to its last whole frame")
