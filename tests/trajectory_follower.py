"""A joint state that follows a trajectory controller's commands, for controller tests."""

from __future__ import annotations

import numpy as np

from hil.controllers import TrajectoryGoal, TrajectoryPoint

DT = 0.002


class Follower:
    """Actual state that tracks the command with a first-order lag (0 = ideal)."""

    def __init__(self, controller, lag: float = 0.0):
        self.controller, self.lag = controller, lag
        n = len(controller.joint_names)
        self.q, self.v, self.t = np.zeros(n), np.zeros(n), 0.0

    def run(self, seconds: float):
        for _ in range(round(seconds / DT)):
            command, _ = self.controller.update(self.t, self.q.copy(), self.v.copy())
            alpha = 1.0 if self.lag == 0 else DT / self.lag
            new_q = self.q + alpha * (command - self.q)
            self.v = (new_q - self.q) / DT
            self.q = new_q
            self.t += DT
        return self.controller.finished()


def goal(names, *points, **kwargs):
    return TrajectoryGoal(tuple(names), tuple(TrajectoryPoint(t, tuple(p), *extra)
                                              for t, p, *extra in points), **kwargs)
