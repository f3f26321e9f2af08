"""The inertia each motor sees (start-up only: what ``hil sim`` tunes its drives on).

For a transmission a = P q the inertia a motor sees with every other joint free to move is
1 / (P W P^T)_kk, W the mobility (inverse inertia) of the robot's joints. MuJoCo's joint
space inertia M (``mj_fullM``) holds the links and the rotors' armature; on a fixed base
W = M^-1. A floating robot moves with what it rests on the ground on:
:func:`ground_constraints` gives those constraints as rows of ``G qdot = 0``, and the
mobility under them is M^-1 - M^-1 G^T (G M^-1 G^T)^+ G M^-1.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

import mujoco
import numpy as np

from hil.description import JointType, RobotDescription
from hil.transmissions import Transmission


class StandingPlant(Protocol):
    """What the inertias are computed from: :class:`hil.plant.plant.Plant`, which calls
    here (named by what is read, so that the two modules import in one direction)."""

    model: mujoco.MjModel
    data: mujoco.MjData
    description: RobotDescription
    transmissions: Sequence[Transmission]

    @property
    def floating(self) -> bool: ...

    def resting_points(self) -> dict[int, list[np.ndarray]]: ...

#: the ground is level: the plant stands a floating robot on a horizontal plane
UP = np.array([0.0, 0.0, 1.0])
#: a continuous joint rolls its body on the ground when the axle's level part is at least
#: this (the sine of its angle to the vertical; hil's bound: an axle within 6 degrees of the
#: vertical spins its body in place, a turntable, not a wheel)
ROLLING_AXLE = 0.1
#: a motor whose mobility the ground constraints cut below this share of its mobility off
#: the ground cannot move while its robot stands: its inertia is infinite (hil's bound,
#: far past any real load: a wheel rolling tests/fixtures/wheeled_arm.urdf sees 7 times its
#: inertia off the ground, a standing quadruped's knee about a hundred; a locked one came
#: out at 4e-16 of it, the pseudo-inverse's rounding)
LOCKED = 1e-9


def motor_inertias(plant: StandingPlant) -> dict[str, float]:
    """Each actuator's inertia seen from its motor shaft, by actuator name (kg·m², or
    math.inf for a motor that the ground holds still); :meth:`Plant.motor_inertias`."""
    model = plant.model
    mass = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, plant.data, mass)
    free = np.linalg.inv(mass)
    mobility = free
    held = ground_constraints(plant)
    if held is not None:
        coupling = free @ held.T
        mobility = free - coupling @ np.linalg.pinv(held @ coupling) @ coupling.T
    inertias = {}
    for transmission in plant.transmissions:
        dofs = [model.joint(j).dofadr[0] for j in transmission.joints]
        matrix = transmission.position_matrix
        grounded = np.diag(matrix @ mobility[np.ix_(dofs, dofs)] @ matrix.T)
        lifted = np.diag(matrix @ free[np.ix_(dofs, dofs)] @ matrix.T)
        inertias.update((name, 1.0 / moves if moves > LOCKED * off else np.inf)
                        for name, moves, off in zip(transmission.actuators, grounded, lifted))
    return inertias


def ground_constraints(plant: StandingPlant) -> np.ndarray | None:
    """What a floating robot's links resting on the ground (:meth:`Plant.resting_points`)
    hold, as rows of ``G qdot = 0`` (each the Jacobian of a point at the middle of a body's
    bottom, along one direction), or None (a fixed base, or nothing resting).

    Feet stay where they are (three rows each): a leg then carries the body, as a standing
    quadruped's drives do (tuned on the leg alone they saw a hundred times the inertia
    they were tuned for, their velocity loops far slower than their position loops, and it
    hopped). A wheel (a body on a continuous joint whose axle is not upright) rolls: its
    contact point neither sinks nor slips along the way it rolls (two rows), so its motor
    moves the robot and sees its mass at the wheel's radius; sideways it is left free (a
    set of fixed wheels that are not all parallel, or plain cylinders standing in for omni
    wheels, would otherwise lock each other). Beside a wheel, what else rests on the
    ground slides on it (one row, held up): a caster or a skid. Pinned too, a ball caster
    fixed to the base locked the wheels, their inertia infinite, their drives tuned to
    velocity_kp inf. hil's choice where MuJoCo gives no rule (its contacts hold by friction
    within a cone and slip past it: MuJoCo's documentation, Computation, "Contact"): a
    swivel caster and a skid do not hold a base back."""
    if not plant.floating:
        return None
    model, data = plant.model, plant.data
    resting = plant.resting_points()
    continuous = {joint.name for joint in plant.description.joints
                  if joint.type is JointType.CONTINUOUS}
    ways = {body: _rolling_way(model, data, body, continuous) for body in resting}
    wheeled = any(way is not None for way in ways.values())
    jacobian = np.zeros((3, model.nv))
    rows = []
    for body, corners in resting.items():
        mujoco.mj_jac(model, data, jacobian, None, np.mean(corners, axis=0), body)
        way = ways[body]
        if way is not None:
            rows.extend((UP @ jacobian, way @ jacobian))
        elif wheeled:
            rows.append(UP @ jacobian)
        else:
            rows.extend(jacobian.copy())
    return np.array(rows) if rows else None


def _rolling_way(model: mujoco.MjModel, data: mujoco.MjData, body: int,
                 continuous: set[str]) -> np.ndarray | None:
    """The level direction a wheel ``body`` rolls along now (world frame, unit), or None
    where the body is not a wheel (no joint of it among the ``continuous`` ones)."""
    first = model.body_jntadr[body]
    for joint in range(first, first + model.body_jntnum[body]):
        if model.joint(joint).name not in continuous:
            continue
        way = np.cross(data.xaxis[joint], UP)
        level = float(np.linalg.norm(way))
        if level >= ROLLING_AXLE:
            return way / level
    return None
