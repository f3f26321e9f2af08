"""A demonstration goal that moves every actuated joint, for first runs and smoke tests."""

from __future__ import annotations

from collections.abc import Collection

import numpy as np

from hil.controllers.goal import TrajectoryGoal, TrajectoryPoint
from hil.description import JointType, RobotDescription

#: revolute swing: at most this far (rad) and this fraction of the range each side
SWING, SWING_FRACTION = 0.5, 0.25
#: peak speed as a fraction of the joint's velocity limit; shortest segment (s)
SPEED_FRACTION, MIN_SEGMENT = 0.5, 1.5
#: keep this fraction of the range away from the limits
MARGIN = 0.05
#: a demo that holds a standing robot's joints lasts at least this long (s)
STAND = 10.0


def demo_goal(robot: RobotDescription, joint_names, current, slower: float = 1.0,
              held: Collection[str] = ()) -> TrajectoryGoal:
    """Rotary joints swing one way, the other way and back to the middle of their swing;
    prismatic joints (grippers) open fully, close and open again; ``held`` joints (those a
    standing robot stands on) stay where they are, for STAND seconds at least.

    ``current`` are the joints' positions now; a joint resting outside its
    swing (e.g. hanging on a limit) is brought into it by the first segment.
    Segments stop at each waypoint (cubic, zero velocity), with peak speed at
    most SPEED_FRACTION of each joint's velocity limit; ``slower`` stretches every
    segment by that factor (see :func:`hil.commissioning.demo_pace.paced_demo`).
    """
    waypoints = np.array([(_inside(robot.joint(name), position),) * 3 if name in held else
                          _waypoints(robot.joint(name), position)
                          for name, position in zip(joint_names, current)]).T   # (3, joints)
    limits = np.array([robot.joint(name).limits.velocity for name in joint_names])
    shortest = max(MIN_SEGMENT, STAND / len(waypoints)) if held else MIN_SEGMENT
    points, time, previous = [], 0.0, np.asarray(current, dtype=float)
    for positions in waypoints:
        # a cubic from rest to rest peaks at 1.5 x the mean speed
        duration = slower * max(shortest, float(np.max(1.5 * np.abs(positions - previous)
                                                       / (SPEED_FRACTION * limits))))
        time += duration
        points.append(TrajectoryPoint(time, tuple(positions), (0.0,) * len(positions)))
        previous = positions
    return TrajectoryGoal(tuple(joint_names), tuple(points))


def _inside(joint, position: float) -> float:
    """``position``, or the nearer limit of a joint that rests beyond it (a loaded joint
    sagged past its end): where it is held."""
    lower, upper = joint.limits.lower, joint.limits.upper
    return position if lower is None or upper is None else float(np.clip(position, lower, upper))


def _waypoints(joint, position: float) -> tuple[float, float, float]:
    lower, upper = joint.limits.lower, joint.limits.upper
    if lower is None or upper is None:           # continuous joint
        return position + SWING, position - SWING, position
    margin = MARGIN * (upper - lower)
    lower, upper = lower + margin, upper - margin
    if joint.type is JointType.PRISMATIC:
        return upper, lower, upper
    swing = min(SWING, SWING_FRACTION * (upper - lower))
    centre = float(np.clip(position, lower + swing, upper - swing))
    return centre + swing, centre - swing, centre
