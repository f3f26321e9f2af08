"""The 3D robot in a recording: every joint's transform (parent link to child) in the rows
of one entity, ``joints``, POSE_RATE rows a second per joint, sent in GROUPED chunks."""

from __future__ import annotations

import numpy as np
import rerun as rr

from hil.description import RobotDescription
from hil.messaging.samples import ControlSamples
from hil.visualisation.columns import Times
from hil.visualisation.entities import GROUPED, RobotEntities
from hil.visualisation.kinematics import JointPoses

#: the 3D robot is posed at most this often (Hz): the eye needs no more
POSE_RATE = 20.0


class PoseLog:
    """Joint transforms for the 3D robot, decimated to POSE_RATE, each row a parent-to-child
    transform (as rerun's tf reads it); frames named by link, after ``prefix``."""

    def __init__(self, entities: RobotEntities, robot: RobotDescription, prefix: str):
        self._entities = entities
        self._poses = JointPoses(robot, prefix)
        self._last = -np.inf
        #: what waits to be sent: (times, translations, quaternions, parent and child frames)
        self._waiting: list[tuple] = []

    def restart(self) -> None:
        """A segment's start: the pose is logged anew with the next batch."""
        self._last = -np.inf

    def log(self, batch: ControlSamples, times: Times) -> None:
        wall = batch.wall_time
        rows = []
        for row, t in enumerate(wall):
            if t - self._last >= 1.0 / POSE_RATE:
                rows.append(row)
                self._last = t
        if not rows:
            return
        rows = np.array(rows)
        positions = dict(zip(batch.joint_names, batch.position[rows].T))
        translations, quaternions, parents, children = self._poses.transforms(positions)
        count = len(translations) // len(rows)              # joints posed per row
        self._waiting.append((times.at(np.repeat(rows, count)), translations, quaternions,
                              parents, children))
        if wall[rows[-1]] - self._waiting[0][0].wall[0] >= GROUPED:
            self.send()

    def send(self) -> None:
        """The poses waiting, as one chunk."""
        waiting = self._waiting
        if not waiting:
            return
        times = Times(np.concatenate([t.wall for t, *_ in waiting]),
                      _joined([t.control for t, *_ in waiting]),
                      _joined([t.sim for t, *_ in waiting]))
        self._entities.recording.send_columns(
            f"{self._entities.root}/joints", indexes=times.columns(),
            columns=rr.Transform3D.columns(
                translation=np.concatenate([w[1] for w in waiting]),
                quaternion=np.concatenate([w[2] for w in waiting]),
                parent_frame=[p for w in waiting for p in w[3]],
                child_frame=[c for w in waiting for c in w[4]]))
        waiting.clear()


def _joined(parts: list[np.ndarray | None]) -> np.ndarray | None:
    """Arrays of one timeline joined; None where any part lacks it (the first poses before
    the sim's clock was heard have no sim time: their group then has none)."""
    return None if any(p is None for p in parts) else np.concatenate(parts)
