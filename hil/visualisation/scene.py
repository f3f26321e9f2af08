"""The bench's scene in a recording: each scene object of the bus config (its shape, and its
pose: fixed, or each sim clock tick for one that moves), the contacts, and a floating base's
frame in the world."""

from __future__ import annotations

import numpy as np
import rerun as rr

from hil.bus_config.types import SceneObject
from hil.description import GeometryKind
from hil.description.rotations import rpy_quaternion
from hil.messaging.scene import SceneState
from hil.visualisation.columns import ScalarTable, Times
from hil.visualisation.entities import RobotEntities

#: contact force arrows: metres of arrow per newton (a 50 g object's weight: 25 mm)
CONTACT_ARROW = 0.05
#: a scene's plane is drawn as a square this wide (m): it is endless in the plant
PLANE_DRAWN = 4.0


class SceneLog:
    """The scene's objects, contacts and floating base (posed in ``base_frame``, the URDF's
    root link's frame)."""

    def __init__(self, entities: RobotEntities, scene: tuple[SceneObject, ...],
                 base_frame: str):
        self._entities = entities
        self._scene = scene
        self._base_frame = base_frame

    def log_static(self) -> None:
        rec, root = self._entities.recording, self._entities.root
        for thing in self._scene:
            rec.log(f"{root}/scene/{thing.name}", _shape(thing), static=True)
            if not thing.movable:       # a moving one is posed by each SceneState
                rec.log(f"{root}/scene/{thing.name}", rr.Transform3D(
                    translation=thing.pose.xyz,
                    quaternion=rr.Quaternion(xyzw=rpy_quaternion(thing.pose.rpy))), static=True)

    def log(self, state: SceneState) -> None:
        """The moving objects' poses, the contacts and a floating base's pose, at the state's
        wall and sim time."""
        times = Times(np.array([state.wall_time]), None, np.array([state.sim_time]))
        indexes = times.columns()
        rec, root = self._entities.recording, self._entities.root
        if state.base is not None:
            position, orientation = state.base
            # the robot's root frame, placed in the recording's own (its entities' root)
            rec.send_columns(f"{root}/base", indexes=indexes, columns=rr.Transform3D.columns(
                translation=[position], quaternion=[np.roll(orientation, -1)],
                parent_frame=["tf#/"], child_frame=[self._base_frame]))
            table = ScalarTable(times)
            table.add(f"{root}/base/position", *position.reshape(3, 1))
            table.send(rec)
        for name, position, orientation in zip(state.names, state.positions,
                                               state.orientations):
            rec.send_columns(f"{root}/scene/{name}", indexes=indexes,
                             columns=rr.Transform3D.columns(
                                 translation=[position],
                                 quaternion=[np.roll(orientation, -1)]))     # w first -> last
        rec.send_columns(f"{root}/scene/contacts", indexes=indexes, columns=[
            *rr.Points3D.columns(positions=state.contact_points).partition([
                len(state.contact_points)]),
            *rr.Arrows3D.columns(origins=state.contact_points,
                                 vectors=CONTACT_ARROW * state.contact_forces).partition([
                len(state.contact_points)])])


def _shape(thing: SceneObject) -> rr.AsComponents:
    """The rerun archetype that draws a scene object's shape, in its own frame."""
    geometry = thing.geometry
    size = geometry.size
    if geometry.kind is GeometryKind.BOX:
        return rr.Boxes3D(half_sizes=[[s / 2 for s in size]])
    if geometry.kind is GeometryKind.SPHERE:
        return rr.Ellipsoids3D(half_sizes=[[size[0]] * 3])
    if geometry.kind is GeometryKind.CYLINDER:
        return rr.Cylinders3D(lengths=[size[1]], radii=[size[0]])
    if geometry.kind is GeometryKind.MESH:
        return rr.Asset3D(path=geometry.mesh)
    return rr.Boxes3D(half_sizes=[[PLANE_DRAWN / 2, PLANE_DRAWN / 2, 0.0005]],
                      centers=[[0.0, 0.0, -0.0005]], colors=[[128, 128, 128, 96]])
