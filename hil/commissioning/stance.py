"""Whether a robot stands on the ground, on what, and what standing asks of its joints.

A robot stands when, with its root free (a floating base) and lowered onto level ground in
its start pose, links on at least two branches touch the ground (its feet, or its wheels
and casters: the body they branch off touching it too is a base resting on the ground, an
arm's base plate, not a stance) and the centre of mass lies over the polygon their
contact shapes span. Each
foot then carries a share of the weight: the least-squares spread of vertical forces that
balances the weight about the centre of mass, none pulling. A joint between the root and a
foot carries the robot; what it holds standing is its part of those forces through the
foot's Jacobian, less gravity's load on it (MuJoCo's ``qfrc_bias``).

``hil init`` gives a robot that stands a floating base, a floor and drives sized for
standing; ``hil up --demo`` holds the joints that carry it where they are (a legged robot
stands, a wheeled one stays put) while the others swing.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import mujoco
import numpy as np

from hil.description import RobotDescription
from hil.description.corrections import massless_free_links
from hil.plant import INITIAL_MARGIN, Plant

#: the centre of mass must lie this far inside the support polygon (m)
SUPPORT_MARGIN = 0.005
#: the standing pose's least squares: iterations, and the damping (m^2)
IK_ITERATIONS = 40
IK_DAMPING = 1e-4


@dataclass(frozen=True)
class Stance:
    """How a robot stands: on ``feet`` (links; wheels where ``wheeled``), with ``carrying``
    the movable joints between its root and a foot, and the load each holds standing."""

    feet: tuple[str, ...]
    wheeled: bool
    carrying: tuple[str, ...]
    loads: dict[str, float]         # N·m or N, by joint

    @property
    def kind(self) -> str:
        return "wheeled" if self.wheeled else "legged"


def stance(robot: RobotDescription, pose: Mapping[str, float] | None = None) -> Stance | None:
    """How ``robot`` stands on level ground in its start pose (``pose`` over hil's own), or
    None if it does not. A base without mass does not (a root link without ``<inertial>``,
    as hand-written URDFs leave it): URDF's tools take it as fixed to the world, and MuJoCo
    cannot float it."""
    if massless_free_links(robot.links, robot.joints):
        return None
    plant = Plant(robot, floating_base=True, start_pose=pose)
    root = plant.base_body
    if root is None:                  # every body on the world has a movable joint of its own
        return None
    model, data = plant.model, plant.data
    corners = {body: points for body, points in plant.resting_points().items()
               if body != root and _descends(model, body, root)}
    if not corners:
        return None
    # the body the feet branch off (a trunk below a base link, say): the nearest common one
    trunk = _common_ancestor(model, list(corners))
    if trunk in corners or len({_branch(model, body, trunk) for body in corners}) < 2:
        return None
    points = np.array([c for body in corners for c in corners[body]])
    centre = data.subtree_com[root][:2]
    if not _inside(centre, _hull(points[:, :2]), SUPPORT_MARGIN):
        return None
    feet = sorted(corners, key=lambda body: model.body(body).name)
    forces = _vertical_forces(np.array([np.mean(corners[body], axis=0)[:2] for body in feet]),
                              centre, float(model.body_subtreemass[root])
                              * float(np.linalg.norm(model.opt.gravity)))
    torques = data.qfrc_bias.copy()
    jacobian = np.zeros((3, model.nv))
    for body, force in zip(feet, forces):
        mujoco.mj_jac(model, data, jacobian, None, np.mean(corners[body], axis=0), body)
        torques -= jacobian[2] * force
    carrying = tuple(name for name in plant.joint_names
                     if any(_descends(model, body, model.joint(name).bodyid[0])
                            for body in feet))
    wheeled = any(robot.joint(name).type.value == "continuous"
                  and model.joint(name).bodyid[0] in feet for name in carrying)
    return Stance(tuple(model.body(body).name for body in feet), wheeled, carrying,
                  {name: abs(float(torques[model.joint(name).dofadr[0]]))
                   for name in carrying})


def standing_pose(robot: RobotDescription, found: Stance) -> dict[str, float]:
    """The joints that carry the robot moved so that each foot stands under the body its leg
    branches off at (its hip) as seen from the side, by damped least squares on the foot's
    forward position, INITIAL_MARGIN of their ranges inside their limits: a stance that
    carries the weight straight down the legs (the feet stay as far apart sideways as they
    were)."""
    plant = Plant(robot)
    model, data = plant.model, plant.data
    feet = [model.body(name).id for name in found.feet]
    trunk = _common_ancestor(model, feet)
    # the trunk's forward direction, level: its x axis (URDF's convention, REP 103)
    forward = data.xmat[trunk].reshape(3, 3)[:, 0] * [1.0, 1.0, 0.0]
    forward /= np.linalg.norm(forward)
    carrying = {model.joint(name).dofadr[0]: model.joint(name) for name in found.carrying}
    for _ in range(IK_ITERATIONS):
        for foot in feet:
            hip = _branch(model, foot, trunk)
            dofs = [dof for dof, joint in carrying.items()
                    if _descends(model, foot, int(joint.bodyid[0]))]
            point = _foot_point(plant, foot)
            miss = forward @ (data.xpos[hip] - point)
            jacobian = np.zeros((3, model.nv))
            mujoco.mj_jac(model, data, jacobian, None, point, foot)
            row = forward @ jacobian[:, dofs]
            step = row * miss / (row @ row + IK_DAMPING)
            for dof, change in zip(dofs, step):
                joint = carrying[dof]
                address = int(joint.qposadr[0])
                value = data.qpos[address] + change
                if joint.limited[0]:          # as far inside its range as hil starts joints
                    low, high = joint.range
                    margin = INITIAL_MARGIN * (high - low)
                    value = np.clip(value, low + margin, high - margin)
                data.qpos[address] = value
        mujoco.mj_kinematics(model, data)
    return {name: float(data.qpos[model.joint(name).qposadr[0]]) for name in found.carrying}


def _foot_point(plant: Plant, foot: int) -> np.ndarray:
    """Where the foot's ground shapes are lowest now (the middle of their bottoms)."""
    model, data = plant.model, plant.data
    points = []
    for geom in plant.ground_shapes:
        if model.geom_bodyid[geom] == foot:
            turn = data.geom_xmat[geom].reshape(3, 3)
            centre, half = model.geom_aabb[geom][:3], model.geom_aabb[geom][3:]
            middle = data.geom_xpos[geom] + turn @ centre
            middle[2] -= np.abs(turn[2]) @ half
            points.append(middle)
    return np.mean(points, axis=0) if points else data.xpos[foot].copy()


def _branch(model: mujoco.MjModel, body: int, ancestor: int) -> int:
    """The child of ``ancestor`` that ``body`` hangs from."""
    while int(model.body_parentid[body]) != ancestor:
        body = int(model.body_parentid[body])
    return body


def _common_ancestor(model: mujoco.MjModel, bodies: list[int]) -> int:
    """The deepest body that every one of ``bodies`` descends from (or is)."""
    def chain(body: int) -> list[int]:
        path = [body]
        while body > 0:
            body = int(model.body_parentid[body])
            path.append(body)
        return path[::-1]

    common = 0
    for level in zip(*map(chain, bodies)):
        if len(set(level)) > 1:
            break
        common = level[0]
    return common


def _descends(model: mujoco.MjModel, body: int, ancestor: int) -> bool:
    while body > 0:
        if body == ancestor:
            return True
        body = int(model.body_parentid[body])
    return False


def _hull(points: np.ndarray) -> np.ndarray:
    """The convex hull of 2D points, counter-clockwise (Andrew's monotone chain; numpy has
    none, and this project takes no SciPy for one polygon)."""
    ordered = sorted(map(tuple, np.round(points, 9)))
    if len(ordered) < 3:
        return np.array(ordered)

    def half(sequence):
        chain: list[tuple[float, float]] = []
        for point in sequence:
            while len(chain) >= 2 and _cross(chain[-2], chain[-1], point) <= 0:
                chain.pop()
            chain.append(point)
        return chain[:-1]

    return np.array(half(ordered) + half(reversed(ordered)))


def _cross(o, a, b) -> float:
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])


def _inside(point: np.ndarray, hull: np.ndarray, margin: float) -> bool:
    """Whether ``point`` lies at least ``margin`` inside the counter-clockwise ``hull``."""
    if len(hull) < 3:
        return False
    for a, b in zip(hull, np.roll(hull, -1, axis=0)):
        edge = b - a
        if _cross(a, b, point) / float(np.linalg.norm(edge)) < margin:
            return False
    return True


def _vertical_forces(feet: np.ndarray, centre: np.ndarray, weight: float) -> np.ndarray:
    """Each foot's share of ``weight`` (N): the least-squares forces whose sum is the weight
    and whose moment about the centre of mass is nought, those that would pull set to
    nought and the rest scaled to carry it all."""
    system = np.vstack([np.ones(len(feet)), (feet - centre).T])
    forces = np.linalg.lstsq(system, np.array([weight, 0.0, 0.0]), rcond=None)[0]
    forces = np.clip(forces, 0.0, None)
    return forces * weight / forces.sum() if forces.sum() > 0 else np.full(len(feet),
                                                                           weight / len(feet))
