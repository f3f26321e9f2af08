"""Joint states of every movable joint, mimic joints computed from their leader."""

from __future__ import annotations

import numpy as np

from hil.description import RobotDescription


class JointStateBroadcaster:
    """Turns the actuated joints' state into the state of every movable joint."""

    def __init__(self, robot: RobotDescription, actuated: tuple[str, ...]):
        self.names = tuple(j.name for j in robot.movable_joints)
        index = {name: i for i, name in enumerate(actuated)}
        self._source = []       # (actuated index, multiplier, offset) per published joint
        for joint in robot.movable_joints:
            if joint.mimic is not None:
                self._source.append((index[joint.mimic.joint], joint.mimic.multiplier,
                                     joint.mimic.offset))
            elif joint.name in index:
                self._source.append((index[joint.name], 1.0, 0.0))
            else:
                self._source.append((None, 0.0, 0.0))     # passive joint: not measured
        self._index = np.array([s[0] if s[0] is not None else 0 for s in self._source])
        self._scale = np.array([s[1] for s in self._source])
        self._offset = np.array([s[2] for s in self._source])
        self._measured = np.array([s[0] is not None for s in self._source])
        self._own = np.array([joint.name in index for joint in robot.movable_joints])

    def compute(self, positions, velocities, efforts):
        """(positions, velocities, efforts) of every movable joint; NaN where unmeasured."""
        p = np.where(self._measured, np.asarray(positions)[self._index] * self._scale
                     + self._offset, np.nan)
        v = np.where(self._measured, np.asarray(velocities)[self._index] * self._scale, np.nan)
        e = np.where(self._own, np.asarray(efforts)[self._index], np.nan)
        return p, v, e
