"""The demo goal at a pace the robot can follow, and the loads it puts on each joint.

The demo (:func:`hil.controllers.demo.demo_goal`) paces itself by the joints' velocity
limits only; a mobile base whose description gives it an arm's effort limit, or a lift
that carries the whole upper body, cannot accelerate that fast. MuJoCo's inverse dynamics
along the demo's path (gravity, inertia and velocity terms) tell each joint's load; the
demo is slowed until moving (all but the gravity load) takes no joint more than
MOTION_SHARE of its effort limit, the rest left to gravity and the drive's loops; a joint
that needs more than EFFORT_SHARE of its limit even so is named. `hil init` sizes drives
for the same demo (the gravity load held along it, not only at the start pose), and `hil
up --demo` runs it.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from dataclasses import dataclass

import mujoco
import numpy as np

from hil.controllers.demo import demo_goal
from hil.controllers.goal import TrajectoryGoal
from hil.controllers.spline import Spline
from hil.description import RobotDescription
from hil.plant import Plant

#: the share of its effort limit the demo's motion may take from a joint (slowed until so)
MOTION_SHARE = 0.3
#: a joint that needs more than this share of its effort limit at the demo's peak is named
EFFORT_SHARE = 0.9
#: the demo is slowed at most this much; a joint that still needs more is named
MOST_SLOWER = 16.0
SAMPLES = 300


@dataclass(frozen=True)
class DemoLoads:
    """Per joint of the demo: the largest effort it needs anywhere along it, and the
    largest gravity load it holds (N·m or N)."""

    peak: dict[str, float]
    holding: dict[str, float]


@dataclass(frozen=True)
class PacedDemo:
    goal: TrajectoryGoal
    slower: float                 # how much the demo was stretched (1: not at all)
    loads: DemoLoads
    notes: tuple[str, ...]        # joints that still need more than EFFORT_SHARE


def paced_demo(robot: RobotDescription, joint_names, current=None,
               held: Collection[str] = (), start_pose: Mapping[str, float] | None = None
               ) -> PacedDemo:
    """The demo goal for ``joint_names`` from ``current`` (None: where the plant starts, at
    ``start_pose`` over hil's own), ``held`` joints staying put, slowed (by at most
    MOST_SLOWER) until its motion takes every joint at most MOTION_SHARE of its effort
    limit; joints that need more than EFFORT_SHARE of it even so are named in the notes."""
    plant = Plant(robot, start_pose=start_pose)
    if current is None:
        start = dict(zip(plant.joint_names, plant.joint_positions().tolist()))
        current = [start[name] for name in joint_names]
    effort = np.array([robot.joint(name).limits.effort for name in joint_names])
    slower = 1.0
    while True:
        goal = demo_goal(robot, joint_names, current, slower, held)
        loads = demo_loads(plant, goal, current)
        motion = np.array([loads.peak[n] - loads.holding[n] for n in joint_names])
        need = float(np.max(motion / np.maximum(MOTION_SHARE * effort, 1e-9)))
        if need <= 1.0 or slower >= MOST_SLOWER:
            break
        # inertia's part falls with the square of the stretch (damping's only with it)
        slower = min(MOST_SLOWER, slower * max(1.1, need ** 0.5))
    notes = tuple(
        f"joint '{n}' needs {loads.peak[n]:.3g} of its {e:.3g} {robot.joint(n).type.effort_unit}"
        f" effort limit in the demo (gravity alone {loads.holding[n]:.3g})"
        for n, e in zip(joint_names, effort) if loads.peak[n] > EFFORT_SHARE * e)
    return PacedDemo(goal, slower, loads, notes)


def demo_loads(plant: Plant, goal: TrajectoryGoal, current) -> DemoLoads:
    """The loads of ``goal``, followed from ``current`` as the controller interpolates it
    (cubic, through rest at each point), from MuJoCo's inverse dynamics of ``plant``."""
    names = goal.joint_names
    times = np.array([p.time_from_start for p in goal.points])
    positions = np.array([p.positions for p in goal.points])
    spline = Spline.between(times, positions, np.zeros_like(positions),
                            np.zeros_like(positions), 3)
    start = np.asarray(current, dtype=float)
    spline.start_from(start, np.zeros_like(start), np.zeros_like(start))
    model, data = plant.model, plant.data
    own = np.array([model.joint(name).dofadr[0] for name in names], dtype=int)
    motion = _motion_map(plant, names)
    peak, holding = np.zeros(len(names)), np.zeros(len(names))
    for t in np.linspace(0.0, spline.end, SAMPLES):
        position, velocity, acceleration = spline.sample(t)
        plant.set_joint_positions(dict(zip(names, position)))      # at rest, mimics follow
        data.qacc[:] = 0.0
        mujoco.mj_inverse(model, data)                              # gravity alone
        holding = np.maximum(holding, np.abs(data.qfrc_inverse[own]))
        data.qvel[:], data.qacc[:] = motion @ velocity, motion @ acceleration
        mujoco.mj_inverse(model, data)
        peak = np.maximum(peak, np.abs(data.qfrc_inverse[own]))
    return DemoLoads(dict(zip(names, peak.tolist())), dict(zip(names, holding.tolist())))


def _motion_map(plant: Plant, names) -> np.ndarray:
    """(nv, joints): the plant's joint velocities for the demo joints' velocities, mimic
    joints moving with their leaders."""
    model = plant.model
    column = {name: i for i, name in enumerate(names)}
    motion = np.zeros((model.nv, len(names)))
    for joint in plant.description.movable_joints:
        dof = model.joint(joint.name).dofadr[0]
        if joint.name in column:
            motion[dof, column[joint.name]] = 1.0
        elif joint.mimic is not None and joint.mimic.joint in column:
            motion[dof, column[joint.mimic.joint]] = joint.mimic.multiplier
    return motion
