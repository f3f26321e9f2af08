"""What a recorded run holds, read back for review without opening a viewer: its segments,
and every fault and reset the controller reported, with its time, so that the moment worth
looking at in an hour's recording is known before the viewer opens (whose "diagnostics"
view jumps there on a click).

Only the diagnostics' chunks are read: a segment closed properly has rerun's manifest
(its footer), and the store loads the chunks the filter asks for; one cut off by a crash
has none and is scanned whole, up to its last flush, as rerun's viewer scans it. A segment
rerun cannot read (cut in the middle of a message, or not a recording at all) is named with
rerun's reason, which gives the offset, and the others are read all the same.
"""

from __future__ import annotations

import datetime
import warnings
from dataclasses import dataclass
from pathlib import Path

import rerun.chunk


@dataclass(frozen=True)
class Diagnostic:
    """A fault or a reset in the recording: when (wall clock; the controller's clock where
    it was recorded, s), how grave, what."""

    wall_time: datetime.datetime
    control_time: float | None
    level: str
    text: str
    segment: Path


@dataclass(frozen=True)
class DamagedSegment:
    """A segment read in part or not at all: which, and rerun's reason (with the offset)."""

    segment: Path
    reason: str
    is_recording: bool        # False: not an .rrd at all, so no viewer should be given it


@dataclass(frozen=True)
class Review:
    """What a recording's segments hold: its diagnostics, oldest first, and the damage."""

    diagnostics: list[Diagnostic]
    damaged: list[DamagedSegment]


def review(files: list[Path]) -> Review:
    """Every fault and reset logged in ``files`` (a recording's segments), and every
    segment that could not be read whole."""
    found, damaged = [], []
    for path in files:
        try:
            chunks, damage = _diagnostic_chunks(path)
        except RuntimeError as exc:              # the reason names the file and the offset
            damaged.append(DamagedSegment(path, str(exc), is_recording=False))
            continue
        if damage is not None:
            damaged.append(DamagedSegment(path, damage, is_recording=True))
        found += [row for chunk in chunks for row in _rows(chunk, path)]
    return Review(sorted(found, key=lambda d: d.wall_time), damaged)


def _diagnostic_chunks(path: Path) -> tuple[list, str | None]:
    """The diagnostics' chunks of a segment, and why it was not read whole (None: it
    was); RuntimeError where it is no recording."""
    damage = None
    with warnings.catch_warnings():              # a crashed segment: rerun warns, then scans
        warnings.simplefilter("ignore")
        reader = rerun.chunk.RrdReader(path)
        try:
            stream = reader.store().stream()
        except RuntimeError:                     # no footer: cut off by a crash
            try:
                stream = reader.stream()
            except RuntimeError as exc:          # cut inside a message: rerun reads none
                return [], str(exc)
            damage = ("no footer: the run did not close it (a crash?); read up to its last "
                      "whole message")
        # one robot's at the root, several robots' each under its name
        return stream.filter(content=["/diagnostics", "/*/diagnostics"],
                             is_static=False).to_chunks(), damage


def _rows(chunk, path: Path) -> list[Diagnostic]:
    batch = chunk.to_record_batch()
    names = batch.schema.names
    walls = [datetime.datetime.fromtimestamp(ns / 1e9, datetime.timezone.utc)
             for ns in batch.column("wall_time").cast("int64").to_pylist()]
    controls = (batch.column("control_time").cast("int64").to_pylist()
                if "control_time" in names else [None] * batch.num_rows)
    texts = batch.column("TextLog:text").to_pylist()
    levels = batch.column("TextLog:level").to_pylist()
    return [Diagnostic(wall, None if control is None else control / 1e9,
                       (level or [""])[0], (text or [""])[0], path)
            for wall, control, text, level in zip(walls, controls, texts, levels)]
