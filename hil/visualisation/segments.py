"""A recording in segments: ``run-0001.rrd``, ``run-0002.rrd``, ..., each closed once it holds
a size or a stretch of time, so that a long run's crash loses at most its last segment and
every segment opens alone in the viewer (the recorder logs the static data again at the
start of each). What ``hil viz --segment`` and ``hil up --segment`` take."""

from __future__ import annotations

import argparse
import glob
import re
import time
from dataclasses import dataclass
from pathlib import Path

from hil.durations import parse_duration

#: --segment's sizes (a duration is written as every time option's: hil.durations)
_SIZES = {"kb": 1e3, "mb": 1e6, "gb": 1e9}


@dataclass(frozen=True)
class SegmentLimit:
    """When a segment is full: at ``bytes`` written, or ``seconds`` after it began."""

    bytes: float | None = None
    seconds: float | None = None

    @classmethod
    def parse(cls, text: str) -> SegmentLimit:
        """``500MB``, ``1GB``, or a duration (``10min``, ``90s``, ``1h``); an
        ArgumentTypeError saying the forms else (an option's type: argparse reports it with
        the option's name)."""
        match = re.fullmatch(r"\s*([0-9]+(?:\.[0-9]+)?)\s*([a-zA-Z]+)\s*", text)
        unit = match.group(2).lower() if match else ""
        if match is not None and unit in _SIZES and float(match.group(1)) > 0:
            return cls(bytes=float(match.group(1)) * _SIZES[unit])
        try:
            seconds = parse_duration(text) if unit else 0.0      # a bare number: no unit given
        except ValueError:
            seconds = 0.0
        if not seconds > 0:
            raise argparse.ArgumentTypeError(
                f"{text!r} is neither a size nor a duration: give e.g. 500MB, 1GB (bytes) or "
                "10min, 90s, 1h (time)")
        return cls(seconds=seconds)

    def __str__(self) -> str:
        return (f"{self.bytes / 1e6:g} MB" if self.bytes is not None
                else f"{self.seconds:g} s")


class Segments:
    """The segment files of a recording saved to ``path``: ``<stem>-0001<suffix>`` and on,
    the next one when the current is full by ``limit``."""

    def __init__(self, path: Path, limit: SegmentLimit, clock=time.monotonic):
        self.path = path
        self.limit = limit
        self._clock = clock
        self.number = 1
        self._began = clock()
        self.closed: list[Path] = []

    @property
    def current(self) -> Path:
        return self.path.with_name(f"{self.path.stem}-{self.number:04d}{self.path.suffix}")

    def full(self) -> bool:
        """Whether the current segment holds its limit (the file's size as written so far,
        or the time since it began)."""
        if self.limit.seconds is not None:
            return self._clock() - self._began >= self.limit.seconds
        try:
            return self.current.stat().st_size >= self.limit.bytes
        except FileNotFoundError:
            return False

    def advance(self) -> Path:
        """Close the current segment (the caller has flushed it): the next one's path."""
        self.closed.append(self.current)
        self.number += 1
        self._began = self._clock()
        return self.current

    def files(self) -> list[Path]:
        """Every segment so far, the current one last."""
        return [*self.closed, self.current]


def segment_files(path: Path) -> list[Path]:
    """The segments of a recording saved as ``path`` (``run.rrd``: ``run-0001.rrd``, ...),
    in order; ``[path]`` where it was saved whole."""
    found = sorted(path.parent.glob(f"{glob.escape(path.stem)}-[0-9][0-9][0-9][0-9]"
                                    f"{glob.escape(path.suffix)}"))
    return found or [path]
