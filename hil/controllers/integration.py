"""``allow_integration_in_goal_trajectories``: the positions (and velocities) a goal's points
leave out, integrated as ros2_controllers' JTC does (jazzy: src/trajectory.cpp,
Trajectory::deduce_from_derivatives, which sample() calls for the segment it is in).

A point without positions is integrated from the point before it (point 0: from the state
before the trajectory, the JTC's set_point_before_trajectory_msg) over the time between
them, ``dt``, by the trapezoid rule::

    velocity = previous velocity + (previous acceleration + its acceleration) / 2 * dt
    position = previous position + (previous velocity + its velocity) / 2 * dt

the velocity only where the point gives none (it then gives accelerations: the JTC refuses
a point with none of the three). Where the point before gives no velocities (or, for a
velocity integrated, no accelerations) they are 0, and that point keeps them: the JTC
resizes its empty fields with 0, so it is then interpolated with them.

jazzy fills a point when sample() first enters the segment that ends at it; a segment it
never enters (a cycle that skips a short segment, a first point due at once) leaves the
point empty and the next segment reads that empty vector (#2282 patched only the last
point). hil integrates every point, in order, before the goal runs: the numbers jazzy
gives where every segment is sampled, and defined where it is not (hil's choice). A first
point without positions that is due when the goal starts has no time to be integrated
over: refused (hil's choice; jazzy reads an empty vector there).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from hil.controllers.goal import GivenFields, GoalArrays, GoalRejected


def integrated(arrays: GoalArrays, p0: np.ndarray, v0: np.ndarray, a0: np.ndarray,
               at: float) -> GoalArrays:
    """``arrays`` with every point's positions, integrated from the state (``p0``, ``v0``,
    ``a0``: the JTC's point before the trajectory) at ``at`` on the goal's clock where a point
    gives none; ``given`` says what each point gives afterwards (the interpolation order)."""
    given = arrays.given
    missing_position = ~given.positions
    if missing_position[0] and arrays.times[0] <= at:
        raise GoalRejected(
            f"point 0 gives no positions and is due at once (time_from_start "
            f"{arrays.times[0]:g} s, the goal's clock now {at:g} s): there is no time to "
            "integrate its positions over (allow_integration_in_goal_trajectories); give it "
            "positions or a later time")
    missing_velocity = missing_position & ~given.velocities
    # row 0: the state before the trajectory; row k + 1: point k
    dt = np.diff(np.concatenate(([at], arrays.times)))[:, None]
    accelerations = np.vstack((a0, arrays.accelerations))
    velocities = _chained(np.vstack((v0, arrays.velocities)),
                          (accelerations[:-1] + accelerations[1:]) / 2 * dt, missing_velocity)
    positions = _chained(np.vstack((p0, arrays.positions)),
                         (velocities[:-1] + velocities[1:]) / 2 * dt, missing_position)
    before = lambda missing: np.append(missing[1:], False)  # noqa: E731  (the point before one)
    filled = GivenFields(
        np.ones_like(missing_position),
        given.velocities | missing_position | before(missing_position),
        given.accelerations | before(missing_velocity))
    return replace(arrays, positions=positions[1:], velocities=velocities[1:],
                   accelerations=arrays.accelerations.copy(), given=filled)


def _chained(rows: np.ndarray, steps: np.ndarray, missing: np.ndarray) -> np.ndarray:
    """``rows`` (the state, then one per point) where each ``missing`` point's row is the row
    before it plus its step: from the last row given, a running sum of the steps."""
    known = np.concatenate(([True], ~missing))
    index = np.arange(len(rows))
    anchor = np.maximum.accumulate(np.where(known, index, 0))
    total = np.vstack((np.zeros((1, rows.shape[1])),
                       np.cumsum(np.where(missing[:, None], steps, 0.0), axis=0)))
    return np.where(known[:, None], rows, rows[anchor] + total - total[anchor])
