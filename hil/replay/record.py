"""``hil replay --record``: the log's and the replay's values of every joint side by side in
a rerun recording, on the ``control_time`` (plant time) and ``cycle`` timelines:
``/replay/<joint>/position/{logged,replayed}`` and ``/replay/<joint>/torque/...``, a plot of
each joint's position and one of its torque."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from hil.replay.report import Report

SIDES = ("logged", "replayed")
#: (report.values column of the logged side, the quantity's name)
QUANTITIES = ((1, "position"), (3, "torque"))


def record_replay(report: Report, robot: str, cycle_hz: float, path: Path) -> None:
    """Write ``report.values`` (a replay run with ``keep_values``) to ``path``."""
    joints = report.statistics.joints if report.statistics is not None else ()
    recording = rr.RecordingStream(f"hil-replay-{robot}")
    views = [rrb.TimeSeriesView(origin=f"/replay/{joint}/{name}", name=f"{joint} {name}")
             for joint in joints for _, name in QUANTITIES]
    recording.save(str(path), default_blueprint=rrb.Blueprint(rrb.Grid(*views)))
    if report.values:
        cycles = np.concatenate([batch[0] for batch in report.values]).astype(np.int64)
        indexes = [rr.TimeColumn("cycle", sequence=cycles),
                   rr.TimeColumn("control_time", duration=cycles / cycle_hz)]
        for column, name in QUANTITIES:
            for side, offset in zip(SIDES, (0, 1)):
                values = np.concatenate([batch[column + offset] for batch in report.values],
                                        axis=1).astype(np.float32)
                for j, joint in enumerate(joints):
                    entity = f"/replay/{joint}/{name}/{side}"
                    recording.log(entity, rr.SeriesLines(names=side), static=True)
                    recording.send_columns(entity, indexes=indexes,
                                           columns=rr.Scalars.columns(scalars=values[j]))
    recording.flush()
    recording.disconnect()
