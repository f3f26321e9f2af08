"""Controllers: they see named joint states and commands only, never drives or frames."""

from hil.controllers.goal import (
    GOAL_TOLERANCE_VIOLATED, HARDWARE_FAULT, INVALID_GOAL, INVALID_JOINTS,
    PATH_TOLERANCE_VIOLATED, SUCCESSFUL, GoalRejected, GoalResult, GoalStatus,
    JointTolerance, TrajectoryGoal, TrajectoryPoint, TrajectoryPoints,
)
from hil.controllers.parameters import JointConstraint, JtcParameters
from hil.controllers.trajectory import ControllerState, JointTrajectoryController

__all__ = [
    "ControllerState", "GOAL_TOLERANCE_VIOLATED", "GoalRejected", "GoalResult",
    "GoalStatus", "HARDWARE_FAULT", "INVALID_GOAL", "INVALID_JOINTS", "JointConstraint", "JointTolerance", "JtcParameters",
    "JointTrajectoryController", "PATH_TOLERANCE_VIOLATED", "SUCCESSFUL", "TrajectoryGoal",
    "TrajectoryPoint", "TrajectoryPoints",
]
