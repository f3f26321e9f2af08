"""The shapes of a robot's links in its MuJoCo model, and the scene they touch.

Each link's ``<collision>`` shapes touch the scene of the bus config (a floor, tables,
objects to grasp), never the robot's other links: URDF collision shapes of neighbouring
links overlap at their joints, and a link whose mesh is missing collides as its
equivalent-inertia box, which overlaps more. Visual geoms touch nothing.
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Protocol

import mujoco
import numpy as np

from hil.description import Geometry, GeometryKind, Link, Pose
from hil.errors import ConfigError

_VISUAL_GROUP = 1
#: MuJoCo's geom group of collision shapes (hidden in its viewer by default)
COLLISION_GROUP = 3
#: contact bits (contype/conaffinity): the robot's links touch the scene, the scene
#: touches the robot and itself
ROBOT_CONTACT, SCENE_CONTACT = 1, 2
#: contacts with torsional friction (condim 4), so a pinched object does not spin
_CONTACT_DIMENSIONS = 4
_TORSIONAL_FRICTION = 0.01      # m (MuJoCo's torsional coefficient: a contact patch's size)
_ROLLING_FRICTION = 0.0001
#: contact stiffness of grasped parts: a 4 ms time constant, critically damped (Menagerie's
#: grippers; MuJoCo's default 20 ms lets a pinched object sink and slip)
CONTACT_SOLREF = (0.004, 1.0)
GRASP_IMPRATIO = 10.0
#: the namespace of the scene's objects in the plant's MuJoCo model (hil's choice): every name
#: the plant gives the robot's parts is a link's or joint's name, or one of them with a suffix
#: (``<link>_collision_<n>``, ``<link>_visual_<n>``, ``<joint>_gear``), or ``floating_base``:
#: a scene object's own name could be any of those (MuJoCo: "repeated name"), ``scene/<name>``
#: none unless a link or joint is named so. hil's messages, the recording (``/scene/<name>``)
#: and Plant.object_pose use the object's own name.
SCENE_NAMESPACE = "scene/"
#: mesh files MuJoCo reads itself; others are drawn as the link's box in the plant
MUJOCO_MESHES = (".stl", ".obj")


def rpy_to_quat(rpy: tuple[float, float, float]) -> np.ndarray:
    """URDF roll-pitch-yaw (fixed axes X, Y, Z) as a MuJoCo quaternion (w, x, y, z)."""
    quat = np.zeros(4)
    mujoco.mju_euler2Quat(quat, np.asarray(rpy, dtype=float), "XYZ")
    return quat


def add_visuals(spec: mujoco.MjSpec, body, link: Link) -> None:
    for number, visual in enumerate(link.visuals):
        geom = _add_shape(spec, body, link, visual.geometry, visual.origin,
                          f"{link.name}_visual_{number}")
        if geom is None:
            continue
        geom.contype, geom.conaffinity, geom.group = 0, 0, _VISUAL_GROUP
        if visual.rgba is not None:
            geom.rgba = visual.rgba


def add_collisions(spec: mujoco.MjSpec, body, link: Link) -> None:
    """The link's ``<collision>`` shapes (a mesh as MuJoCo's convex hull of it), touching the
    scene only (ROBOT_CONTACT)."""
    for number, collision in enumerate(link.collisions):
        name = f"{link.name}_collision_{number}"
        geom = _add_shape(spec, body, link, collision.geometry, collision.origin, name)
        if geom is None:
            continue
        geom.name = name
        geom.contype, geom.conaffinity, geom.group = ROBOT_CONTACT, SCENE_CONTACT, COLLISION_GROUP
        geom.condim = _CONTACT_DIMENSIONS
        geom.solref = CONTACT_SOLREF


def _add_shape(spec: mujoco.MjSpec, body, link: Link, geometry: Geometry, origin: Pose,
               name: str):
    """A massless geom of the shape on the body (the body's inertia is the URDF's): a mesh
    MuJoCo cannot read (DAE, ASCII STL: the recording draws it) or a missing one becomes
    the link's equivalent-inertia box; None where there is nothing to add."""
    mesh = geometry.mesh
    if mesh is not None and unreadable_mesh(mesh) is None:
        # shell inertia never fails on an open mesh; the geom is massless anyway
        spec.add_mesh(name=name, file=str(mesh), scale=list(geometry.size),
                      inertia=mujoco.mjtMeshInertia.mjMESH_INERTIA_SHELL)
        kind, size = mujoco.mjtGeom.mjGEOM_MESH, [0.0, 0.0, 0.0]
    elif geometry.kind is GeometryKind.MESH or not geometry.size:
        if link.inertial is None:
            return None
        kind, size = mujoco.mjtGeom.mjGEOM_BOX, [s / 2 for s in link.inertial.equivalent_box()]
        origin = link.inertial.origin
    else:
        kind, size = _primitive(geometry)
    geom = body.add_geom(type=kind, size=size)
    if kind == mujoco.mjtGeom.mjGEOM_MESH:
        geom.meshname = name
    geom.pos, geom.quat = origin.xyz, rpy_to_quat(origin.rpy)
    geom.mass = 0.0
    return geom


def _primitive(geometry: Geometry) -> tuple[mujoco.mjtGeom, list[float]]:
    """MuJoCo's type and size (half sizes) of a box, cylinder, sphere or plane."""
    size = geometry.size
    if geometry.kind is GeometryKind.BOX:
        return mujoco.mjtGeom.mjGEOM_BOX, [s / 2 for s in size]
    if geometry.kind is GeometryKind.CYLINDER:
        return mujoco.mjtGeom.mjGEOM_CYLINDER, [size[0], size[1] / 2, 0.0]
    if geometry.kind is GeometryKind.SPHERE:
        return mujoco.mjtGeom.mjGEOM_SPHERE, [size[0], 0.0, 0.0]
    # a plane's size only draws it (10 m square); it touches whatever is below its z = 0
    return mujoco.mjtGeom.mjGEOM_PLANE, [5.0, 5.0, 0.1]


class ScenePart(Protocol):
    """A thing placed in the robot's world (a bus config's ``SceneObject`` is one)."""

    name: str
    geometry: Geometry
    pose: Pose
    mass: float                  # kg; 0: fixed in the world
    friction: float


def scene_name(name: str) -> str:
    """The name of a scene object's body, geom, mesh and joint in the plant's MuJoCo model
    (SCENE_NAMESPACE)."""
    return SCENE_NAMESPACE + name


def add_scene(spec: mujoco.MjSpec, scene: tuple[ScenePart, ...]) -> None:
    """Each part as a body of the world: with a mass, free to move (its inertia that of a
    uniform solid of its shape); without, fixed. Parts touch the robot and each other."""
    # the robot's parts are in the spec: their names begin with their links' and joints'
    claimed = [e.name for e in (*spec.bodies, *spec.joints) if e.name.startswith(SCENE_NAMESPACE)]
    if scene and claimed:
        raise ConfigError.single(f"the robot's link or joint '{claimed[0]}' is named as hil names "
                                 f"the scene's objects in the plant ('{SCENE_NAMESPACE}<name>')",
                                 hint="rename that link or joint, or leave out the scene")
    for part in scene:
        _add_part(spec, part)
    if not scene:
        # nothing for the links to touch: no collision detection at all (a share of every
        # plant step of the shipped arms: docs/performance.md, "2026-12-06, later: figures
        # from code comments")
        spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT
    if any(part.mass > 0 for part in scene):
        # what holds a grasp (MuJoCo's "Preventing slip", Menagerie's grippers): elliptic
        # friction cones, and impratio 10 so that friction is as stiff as the normal force
        spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
        spec.option.impratio = GRASP_IMPRATIO


def _add_part(spec: mujoco.MjSpec, part: ScenePart) -> None:
    name = scene_name(part.name)
    body = spec.worldbody.add_body(name=name)
    body.pos, body.quat = part.pose.xyz, rpy_to_quat(part.pose.rpy)
    if part.geometry.kind is GeometryKind.MESH:
        spec.add_mesh(name=name, file=str(part.geometry.mesh), scale=list(part.geometry.size))
        geom = body.add_geom(type=mujoco.mjtGeom.mjGEOM_MESH, meshname=name)
    else:
        kind, size = _primitive(part.geometry)
        geom = body.add_geom(type=kind, size=size)
    geom.name = name
    geom.contype, geom.conaffinity = SCENE_CONTACT, ROBOT_CONTACT | SCENE_CONTACT
    geom.friction = [part.friction, _TORSIONAL_FRICTION, _ROLLING_FRICTION]
    geom.condim = _CONTACT_DIMENSIONS
    geom.solref = CONTACT_SOLREF
    if part.mass > 0:
        body.add_freejoint(name=name)
        geom.mass = part.mass        # MuJoCo takes the inertia of the solid from it
        body.explicitinertial = False


@functools.cache
def unreadable_mesh(path: Path) -> str | None:
    """Why MuJoCo cannot read the mesh file (a format it has no reader for, an ASCII STL,
    a broken file), or None if it can."""
    if path.suffix.lower() not in MUJOCO_MESHES:
        return f"MuJoCo reads {' and '.join(MUJOCO_MESHES)} meshes, not {path.suffix}"
    probe = mujoco.MjSpec()
    probe.add_mesh(name="probe", file=str(path),
                   inertia=mujoco.mjtMeshInertia.mjMESH_INERTIA_SHELL)
    try:
        probe.compile()
    except ValueError as exc:
        return " ".join(str(exc).split()).removeprefix("Error: ").split(" Element name")[0]
    return None
