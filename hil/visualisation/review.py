"""What a recorded run holds, read back for review without opening a viewer: its segments,
every fault and reset the controller reported, with its time, so that the moment worth
looking at in an hour's recording is known before the viewer opens (whose "diagnostics"
view jumps there on a click), and per robot a summary: cycles, duration, each joint's
tracking error (RMS, largest and when) and the control loop's period.

Only the diagnostics' chunks are read: a segment closed properly has rerun's manifest
(its footer), and the store loads the chunks the filter asks for; one cut off by a crash
has none and is scanned whole, up to its last flush, as rerun's viewer scans it. A segment
rerun cannot read (cut in the middle of a message, or not a recording at all) is named with
rerun's reason, which gives the offset, and the others are read all the same. A file that
is no regular file (a FIFO: rerun's RrdReader waited on one for good, measured
2026-12-06 with rerun-sdk 0.41; a device) or over MAX_RECORDING_BYTES is
refused before rerun opens it (:func:`hil.input_files.open_input_stream`).
"""

from __future__ import annotations

import datetime
import math
import re
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import rerun.chunk

from hil.input_files import open_input_stream

#: the largest recording file a review reads (hil's choice): some 18 hours of a run at what
#: a loaded host's run records a second (docs/performance.md, "2026-11-26: the week's
#: figures"); a longer one is recorded in segments (--segment), each a file of its own
MAX_RECORDING_BYTES = 16 * 2**30

#: the entities a review reads, at the root or under a robot's name
_WANTED = re.compile(r"^(?:/(?P<robot>[^/]+))?/(?P<what>diagnostics|cycle|loop/stalls/"
                     r"(?P<process>[^/]+))$")
#: the model of the one robot of a recording at its root: rerun's URDF loader puts the tree
#: under the prefix hil's recorder gives ("robot"), rooted at the robot's name
#: (hil.visualisation.recorder.RunRecorder); a namespaced robot's name is its entities' root
_MODEL = re.compile(r"^/robot/(?P<robot>[^/]+)$")
_COMPONENTS = ("TextLog:text", "TextLog:level", "Scalars:scalars", "SeriesLines:names",
               "CoordinateFrame:frame")
#: a ``cycle`` series of a joint's tracking error (hil.visualisation.blueprint.CycleSeries)
_ERROR_SERIES = re.compile(r"^(?P<joint>.+) error \[(?P<unit>[^\]]+)\]$")


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


@dataclass
class JointTracking:
    """One joint's tracking error over a run: reference minus measured position."""

    joint: str
    unit: str
    column: int                      # its series in the ``cycle`` rows
    max: float = 0.0
    #: the controller's clock (s) at the largest error
    max_at: float | None = None
    _squares: float = 0.0
    _count: int = 0

    @property
    def rms(self) -> float:
        return math.sqrt(self._squares / self._count) if self._count else 0.0

    def add(self, errors: np.ndarray, times: np.ndarray) -> None:
        finite = np.isfinite(errors)
        errors, times = errors[finite], times[finite]
        if not len(errors):
            return
        self._squares += float(np.sum(np.square(errors, dtype=np.float64)))
        self._count += len(errors)
        largest = int(np.argmax(np.abs(errors)))
        if abs(errors[largest]) > self.max:
            self.max, self.max_at = float(abs(errors[largest])), float(times[largest])


@dataclass
class RunSummary:
    """One robot's run in a recording (its ``cycle`` entity): cycles recorded, the span of
    the controller's clock, each joint's tracking, the loop's period (ms; None in lock-step,
    which records none)."""

    robot: str                       # the robot's name ("" where the recording has none)
    cycles: int = 0
    first: float | None = None       # the controller's clock, s
    last: float | None = None
    joints: dict[str, JointTracking] = field(default_factory=dict)
    period_max_ms: float | None = None
    #: per real-time process (sim, control, transport): its stalls' count and the longest (ms)
    stalls: dict[str, tuple[int, float]] = field(default_factory=dict)
    _period_sum: float = 0.0          # ms, over the cycles that recorded a period
    _periods: int = 0

    @property
    def duration(self) -> float:
        return 0.0 if self.first is None else self.last - self.first

    @property
    def period_mean_ms(self) -> float | None:
        return self._period_sum / self._periods if self._periods else None


@dataclass(frozen=True)
class Review:
    """What a recording's segments hold: its diagnostics, oldest first, the damage, and a
    summary per robot."""

    diagnostics: list[Diagnostic]
    damaged: list[DamagedSegment]
    runs: list[RunSummary] = field(default_factory=list)


def review(files: list[Path]) -> Review:
    """Every fault and reset logged in ``files`` (a recording's segments), every segment
    that could not be read whole, and each robot's run summary."""
    for path in files:
        open_input_stream(path, "recording", "give the --save of hil up or hil viz (a .rrd "
                          "file; a longer run in segments: --segment)",
                          MAX_RECORDING_BYTES).close()
    found, damaged = [], []
    runs: dict[str, RunSummary] = {}
    at_root = ""                     # the name of the robot whose entities are at the root
    for path in files:
        try:
            chunks, damage = _chunks(path)
        except RuntimeError as exc:              # the reason names the file and the offset
            damaged.append(DamagedSegment(path, str(exc), is_recording=False))
            continue
        if damage is not None:
            damaged.append(DamagedSegment(path, damage, is_recording=True))
        for chunk in chunks:
            model = _MODEL.match(chunk.entity_path)
            if model:
                at_root = model["robot"]
                continue
            wanted = _WANTED.match(chunk.entity_path)
            robot = wanted["robot"] or ""
            if wanted["what"] == "diagnostics":
                found += _rows(chunk, path)
            elif wanted["process"]:
                _count_stalls(runs.setdefault(robot, RunSummary(robot)), wanted["process"], chunk)
            else:
                _summarise(runs.setdefault(robot, RunSummary(robot)), chunk)
    if "" in runs:
        runs[""].robot = at_root
    return Review(sorted(found, key=lambda d: d.wall_time), damaged,
                  [run for _, run in sorted(runs.items()) if run.cycles])


def _summarise(run: RunSummary, chunk) -> None:
    """Adds a ``cycle`` chunk (its series' names, or its rows) to the run's figures."""
    batch = chunk.to_record_batch()
    if chunk.is_static:
        for k, name in enumerate(batch.column("SeriesLines:names").to_pylist()[-1] or []):
            matched = _ERROR_SERIES.match(name)
            if matched and matched["joint"] not in run.joints:
                run.joints[matched["joint"]] = JointTracking(matched["joint"], matched["unit"], k)
        return
    if "control_time" not in batch.schema.names or not run.joints:
        return
    times = np.array(batch.column("control_time").cast("int64").to_pylist()) / 1e9
    values = np.array(batch.column("Scalars:scalars").to_pylist(), dtype=np.float32)
    run.cycles += len(times)
    run.first = float(times.min()) if run.first is None else min(run.first, float(times.min()))
    run.last = float(times.max()) if run.last is None else max(run.last, float(times.max()))
    for tracking in run.joints.values():
        tracking.add(values[:, tracking.column], times)
    periods = values[:, -2][np.isfinite(values[:, -2])]     # LOOP_SERIES: period, round trip
    if len(periods):
        run._period_sum += float(periods.sum(dtype=np.float64))
        run._periods += len(periods)
        run.period_max_ms = max(run.period_max_ms or 0.0, float(periods.max()))


def _count_stalls(run: RunSummary, process: str, chunk) -> None:
    if chunk.is_static:
        return
    rows = [values for values in chunk.to_record_batch().column("Scalars:scalars").to_pylist()
            if values]
    # a row: the interval's worst stall (ms) and its count (a row per stall before)
    count, longest = run.stalls.get(process, (0, 0.0))
    run.stalls[process] = (count + sum(int(row[1]) if len(row) > 1 else 1 for row in rows),
                           max([longest, *(row[0] for row in rows)]))


def _chunks(path: Path) -> tuple[list, str | None]:
    """The diagnostics' and the cycles' chunks of a segment, and why it was not read whole
    (None: it was); RuntimeError where it is no recording."""
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
        # by component (an entity path filter has no wildcard for one robot's name): the
        # text logs and scalar series, not the poses and geometry that make most of a run
        chunks = stream.filter(components=list(_COMPONENTS)).to_chunks()
    # one robot's at the root, several robots' each under its name; the series' names
    # (static) before the rows they name
    return sorted((chunk for chunk in chunks if (_WANTED.match(chunk.entity_path) and not (
        chunk.is_static and chunk.entity_path.endswith("/diagnostics"))) or (
        chunk.is_static and _MODEL.match(chunk.entity_path))),
        key=lambda chunk: not chunk.is_static), damage


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
