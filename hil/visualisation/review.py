"""What a recorded run holds, read back for review without opening a viewer: its segments,
and every fault and reset the controller reported, with its time, so that the moment worth
looking at in an hour's recording is known before the viewer opens (whose "diagnostics"
view jumps there on a click).

Only the diagnostics' chunks are read: a segment closed properly has rerun's manifest
(its footer), and the store loads the chunks the filter asks for; one cut off by a crash
has none and is scanned whole, up to its last flush, as rerun's viewer scans it.
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


def diagnostics(files: list[Path]) -> list[Diagnostic]:
    """Every fault and reset logged in ``files`` (a recording's segments), oldest first."""
    found = []
    for path in files:
        with warnings.catch_warnings():          # a crashed segment: rerun warns, then scans
            warnings.simplefilter("ignore")
            reader = rerun.chunk.RrdReader(path)
            try:
                stream = reader.store().stream()
            except RuntimeError:                 # no footer: cut off by a crash
                stream = reader.stream()
            # one robot's at the root, several robots' each under its name
            chunks = stream.filter(content=["/diagnostics", "/*/diagnostics"],
                                   is_static=False).to_chunks()
        for chunk in chunks:
            batch = chunk.to_record_batch()
            names = batch.schema.names
            walls = [datetime.datetime.fromtimestamp(ns / 1e9, datetime.timezone.utc)
                     for ns in batch.column("wall_time").cast("int64").to_pylist()]
            controls = (batch.column("control_time").cast("int64").to_pylist()
                        if "control_time" in names else [None] * batch.num_rows)
            texts = batch.column("TextLog:text").to_pylist()
            levels = batch.column("TextLog:level").to_pylist()
            for wall, control, text, level in zip(walls, controls, texts, levels):
                found.append(Diagnostic(wall, None if control is None else control / 1e9,
                                        (level or [""])[0], (text or [""])[0], path))
    return sorted(found, key=lambda d: d.wall_time)
