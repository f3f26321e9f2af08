"""Where one robot's rows go in a recording, shared by the recorder's parts."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import rerun as rr

from hil.visualisation.columns import SimTimeMap, Times

#: the poses and the bus loads are sent in chunks of this many seconds: rerun's file sink
#: keeps an index entry per chunk (and per column of it) until the file is closed, so a
#: chunk of each every 100 ms grew the visualiser's memory without end (docs/performance.md,
#: "2026-11-26: the week's figures")
GROUPED = 0.5


@dataclass(frozen=True)
class RobotEntities:
    """Where one robot's entities go: its recording, their root ("" or "/<robot>": the
    recorder's module doc), and the plant's clock that puts rows on the sim's timeline."""

    recording: rr.RecordingStream
    root: str
    sim_time: SimTimeMap

    def times(self, wall: np.ndarray, control: np.ndarray | None = None) -> Times:
        """Rows at these wall (and controller) times; on sim time too once the sim is heard."""
        return Times(wall, control, self.sim_time(wall))
