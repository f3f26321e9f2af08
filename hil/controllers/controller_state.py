"""What the joint trajectory controller reports each cycle: control_msgs'
JointTrajectoryControllerState and the FollowJointTrajectory feedback fields."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass
class ControllerState:
    """What the controller reports each cycle (control_msgs feedback fields)."""

    time: float
    joint_names: tuple[str, ...]
    desired_positions: np.ndarray
    desired_velocities: np.ndarray
    actual_positions: np.ndarray
    actual_velocities: np.ndarray
    goal_id: str | None
    #: the trajectory point the active goal moves to now (control_msgs 6's feedback
    #: ``index``: "the currently used point"); 0 before it starts and without a goal
    point_index: int = 0
    errors: np.ndarray = field(init=False)

    def __post_init__(self):
        self.errors = self.desired_positions - self.actual_positions
