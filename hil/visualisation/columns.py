"""Columns of a recording: the timelines of a batch of rows, and scalar series sent as
columns (one chunk per entity and batch, rerun's ``send_columns``)."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np
import pyarrow as pa
import rerun as rr


class SimTimeMap:
    """The plant's time at given wall-clock times, from (wall, sim) pairs the sim publishes.

    Inside the pairs: linear interpolation. After the last: extrapolated with
    the latest rate (1 in real time; the speed-up in lock-step).
    """

    def __init__(self, keep: int = 400):
        self._wall: deque[float] = deque(maxlen=keep)
        self._sim: deque[float] = deque(maxlen=keep)

    def add(self, wall: float, sim: float) -> None:
        if self._wall and wall <= self._wall[-1]:
            return
        if self._sim and sim < self._sim[-1]:       # the sim restarted: forget the old run
            self._wall.clear()
            self._sim.clear()
        self._wall.append(wall)
        self._sim.append(sim)

    def __call__(self, wall_times: np.ndarray) -> np.ndarray | None:
        if not self._wall:
            return None
        wall, sim = np.array(self._wall), np.array(self._sim)
        rate = 1.0 if len(wall) < 2 else (sim[-1] - sim[-2]) / (wall[-1] - wall[-2])
        mapped = np.interp(wall_times, wall, sim)
        after = wall_times > wall[-1]
        mapped[after] = sim[-1] + rate * (wall_times[after] - wall[-1])
        before = wall_times < wall[0]
        mapped[before] = sim[0] + (wall_times[before] - wall[0])
        return mapped


@dataclass(frozen=True)
class Times:
    """The times of a batch's rows on each timeline (sim time may be unknown)."""

    wall: np.ndarray
    control: np.ndarray | None
    sim: np.ndarray | None

    def at(self, rows: np.ndarray) -> Times:
        """These times at ``rows`` only."""
        return Times(self.wall[rows], None if self.control is None else self.control[rows],
                      None if self.sim is None else self.sim[rows])

    def named(self) -> list[tuple[str, np.ndarray]]:
        return [(name, values) for name, values in (("wall_time", self.wall),
                                                    ("control_time", self.control),
                                                    ("sim_time", self.sim))
                if values is not None]

    def columns(self, rows: np.ndarray | slice = slice(None)) -> list[rr.TimeColumn]:
        columns = [rr.TimeColumn("wall_time", timestamp=self.wall[rows])]
        if self.control is not None:
            columns.append(rr.TimeColumn("control_time", duration=self.control[rows]))
        if self.sim is not None:
            columns.append(rr.TimeColumn("sim_time", duration=self.sim[rows]))
        return columns


class ScalarTable:
    """Scalar series of many entities on the same rows, sent as one Arrow record batch.

    The ``rerun:*`` field metadata is rerun's documented column classification
    (``Chunk.from_record_batch``): which columns are timelines, and which entity
    and component every other column is.
    """

    def __init__(self, times: Times):
        self._fields, self._columns = [], []
        for name, values in times.named():
            kind = pa.timestamp("ns") if name == "wall_time" else pa.duration("ns")
            self._fields.append(pa.field(name, kind, metadata={
                "rerun:kind": "index", "rerun:index_name": name}))
            self._columns.append(pa.array(np.round(values * 1e9).astype(np.int64), kind))

    def add(self, entity: str, *series: np.ndarray) -> None:
        """One row per time, one scalar per series (as many series as lines on the plot)."""
        self.add_rows(entity, np.column_stack(series))

    def add_rows(self, entity: str, rows: np.ndarray) -> None:
        """One row per time of ``rows`` (times x series), as Float64: rerun's schema for the
        Scalar component (`rerun rrd verify` rejects a Float32 column, which the viewer
        shows). Values the recorder rounded to 4-byte floats keep their zero low bits, which
        the recording's compression takes back."""
        kind = pa.float64()
        rows = rows.astype(np.float64)
        self._fields.append(pa.field("Scalars:scalars", pa.list_(kind), metadata={
            "rerun:kind": "data", "rerun:entity_path": entity,
            "rerun:archetype": "rerun.archetypes.Scalars", "rerun:component": "Scalars:scalars",
            "rerun:component_type": "rerun.components.Scalar"}))
        offsets = np.arange(0, rows.size + 1, max(rows.shape[1], 1), dtype=np.int32)
        self._columns.append(pa.ListArray.from_arrays(pa.array(offsets),
                                                      pa.array(rows.ravel(), kind)))

    def send(self, recording: rr.RecordingStream) -> None:
        rr.send_record_batch(pa.RecordBatch.from_arrays(self._columns,
                                                        schema=pa.schema(self._fields)),
                             recording=recording)
