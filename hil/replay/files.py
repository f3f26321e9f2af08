"""A CAN log's files as a replay reads them: one file in a format python-can reads here, or a
folder of a log per bus, each named after its bus (``arm.blf``: what
:meth:`hil.testing.DrivesBench.log_to` and the ``hil_drives`` fixture write), read as one
log in time order (the module doc of :mod:`hil.replay.log`); and whether a log is whole.

Every file is read through bounds (hil's choices, where python-can sets none): a regular
file (:func:`hil.input_files.open_input_stream`: a FIFO hung the reader, ``/dev/zero``
filled the memory) of at most MAX_LOG_BYTES, at most MAX_LOG_FRAMES frames in all, a text
log's line at most MAX_LINE_CHARS, a BLF object at most MAX_OBJECT_BYTES; the file
python-can reads is the one checked (it is given the open file, never the name again)."""

from __future__ import annotations

import heapq
import io
import locale
import os
import struct
import zlib
from collections.abc import Iterator
from pathlib import Path

import can
import can.io.mf4
from can.io.blf import BLFParseError
from can.io.generic import MessageReader, TextIOMessageReader

from hil.errors import ConfigError, HilError
from hil.input_files import open_input_stream, size_in_words

#: the largest log file hil reads: a text log (ASC, candump: 45-70 bytes a frame) of
#: MAX_LOG_FRAMES fits, as a BLF of far more does (about 5.3 bytes a frame:
#: tests/fixtures/pigot_real_time.can.blf holds 116,882 frames in 621,302 bytes)
MAX_LOG_BYTES = 8 * 2**30
#: the most frames a replay reads (all of a folder's files together): a six-drive robot at
#: 1 kHz puts some 19,000 frames a second on its buses (three PDOs a drive and a SYNC), so
#: about 90 minutes of it; replayed at the ur3 demo's 60,000 frames a second (docs/replay.md,
#: "Speed"), half an hour
MAX_LOG_FRAMES = 100_000_000
#: the longest line of a text log (characters): a CAN FD frame of 64 bytes is some 300
MAX_LINE_CHARS = 64 * 1024
#: the largest object of a BLF: python-can writes containers of 128 KiB (BLFWriter's
#: max_container_size), Vector's are of that order
MAX_OBJECT_BYTES = 16 * 2**20

#: the formats hil reads, by suffix (python-can's LogReader's, given an open file)
READERS: dict[str, type[MessageReader]] = {
    ".blf": can.BLFReader, ".asc": can.ASCReader, ".log": can.CanutilsLogReader,
    ".csv": can.CSVReader, ".trc": can.TRCReader,
    **({".mf4": can.MF4Reader} if can.io.mf4.asammdf is not None else {})}
#: python-can's other formats, each refused with why and what to do
REFUSED = {
    ".mf4": "python-can reads MF4 with asammdf, which is not installed here: pip install "
            "asammdf",
    ".db": "python-can's SQLite log is opened by its name, not as a checked file: convert "
           "it: python -m can.logconvert LOG.db LOG.blf",
    ".gz": "a compressed log's size bounds nothing of what it holds: decompress it first "
           "(gunzip)",
}
#: the suffixes of a folder's files that are logs (read, or refused by name)
LOG_SUFFIXES = tuple(READERS) + tuple(s for s in REFUSED if s not in READERS)
#: what to give, in every refusal
FORMATS_HINT = (f"give a {', '.join(READERS)} (.log: candump's text) file, or a folder of "
                "them, one per bus named after it")

#: what python-can's readers raise on a damaged file (BLF: a bad header or object, a
#: container whose zlib stream is corrupt)
_DAMAGED = (ValueError, OSError, EOFError, struct.error, BLFParseError, zlib.error)


def log_files(path: Path) -> list[Path]:
    """The files of a log: ``path``, or a folder's logs (one per bus, named after it)."""
    if not path.is_dir():
        return [path]
    found = sorted(f for f in path.iterdir() if f.suffix.lower() in LOG_SUFFIXES)
    if not found:
        raise ConfigError.single(f"{path} is a folder with no CAN log in it",
                                 hint="give a log file, or a folder of a log per bus named after "
                                      f"it ({', '.join(f'BUS{s}' for s in READERS)})")
    return found


def read_log(path: Path) -> Iterator[can.Message]:
    """The frames of a log (a clear error where python-can cannot read it, or past a bound:
    the module doc); of a folder's logs, merged by time, each frame's channel the name of
    its file (its bus')."""
    files = log_files(path)

    def named(file: Path) -> Iterator[can.Message]:
        for msg in _read_file(file):
            msg.channel = file.stem
            yield msg
    merged = (_read_file(path) if files == [path]
              else heapq.merge(*map(named, files), key=lambda msg: msg.timestamp))
    for count, msg in enumerate(merged, 1):
        if count > MAX_LOG_FRAMES:
            raise ConfigError.single(
                f"CAN log '{path}' holds over {MAX_LOG_FRAMES:,} frames, the most hil replay "
                "reads", hint="replay a stretch of it: write the frames of a few minutes to a "
                              "log of their own (python-can's LogReader and Logger)")
        yield msg


def open_log(path: Path) -> MessageReader:
    """python-can's reader of the log file ``path``, given the file open and checked (the
    module doc's bounds); ConfigError naming it where hil does not read it."""
    suffix = path.suffix.lower()
    if suffix not in READERS:
        said = REFUSED.get(suffix, f"'{path.suffix}' is no CAN log format python-can reads")
        raise ConfigError.single(f"cannot read CAN log '{path}': {said}", hint=FORMATS_HINT)
    stream = open_input_stream(path, "CAN log", FORMATS_HINT, MAX_LOG_BYTES)
    reader_type = READERS[suffix]
    if issubclass(reader_type, TextIOMessageReader):
        # python-can's own default encoding for a text log it opens by name
        file = _BoundedLines(stream, path, encoding=locale.getpreferredencoding(False))
    elif reader_type is can.BLFReader:
        file = _BoundedReads(stream, path)
    else:
        file = stream
    try:
        return reader_type(file=file)
    except BaseException as exc:
        stream.close()
        if isinstance(exc, (*_DAMAGED, ImportError)):
            raise ConfigError.single(f"cannot read CAN log '{path}': {exc}",
                                     hint=FORMATS_HINT) from None
        raise


class _BoundedLines(io.TextIOWrapper):
    """A text log read line by line, a line no longer than MAX_LINE_CHARS: a file without a
    line end is not read whole into one string."""

    def __init__(self, stream: io.BufferedReader, path: Path, encoding: str):
        super().__init__(stream, encoding=encoding)
        self.path = path

    def __next__(self) -> str:
        line = self.readline(MAX_LINE_CHARS + 1)
        if not line:
            raise StopIteration
        if len(line) > MAX_LINE_CHARS:
            raise ConfigError.single(f"CAN log '{self.path}' has a line of over {MAX_LINE_CHARS:,} "
                                     "characters: no text log of CAN frames", hint=FORMATS_HINT)
        return line


class _BoundedReads:
    """A BLF read object by object, none over MAX_OBJECT_BYTES: a header that claims
    gigabytes is not read whole into memory."""

    def __init__(self, stream: io.BufferedReader, path: Path):
        self._stream, self.path = stream, path

    def read(self, size: int = -1) -> bytes:
        if not 0 <= size <= MAX_OBJECT_BYTES:
            raise ConfigError.single(
                f"CAN log '{self.path}' is damaged: at byte {self._stream.tell()} it gives a "
                f"length of {size:,} bytes, where a BLF's objects are of 0 to "
                f"{size_in_words(MAX_OBJECT_BYTES)}",
                hint="a damaged file: replay a copy made before it was damaged")
        return self._stream.read(size)

    def __getattr__(self, name: str):
        return getattr(self._stream, name)          # close, tell, ...: the file's own


def _read_file(path: Path) -> Iterator[can.Message]:
    reader = open_log(path)
    try:
        yield from reader
    except _DAMAGED as exc:
        raise ConfigError.single(f"CAN log '{path}' is damaged: {exc}",
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
        reader = open_log(path)
    except HilError:
        return None                           # read_log names what is wrong with it
    said, size = reader.file_size, os.fstat(reader.file.fileno()).st_size
    reader.stop()
    if said == size:
        return None
    return (f"its header gives {said} bytes and it has {size}: cut off, or never closed (a "
            "crash?); replayed up to its last whole frame")
