"""The robot as rerun's URDF loader is to draw it, written from hil's description.

rerun finds ``package://`` meshes through ``ROS_PACKAGE_PATH`` only, and would draw what the
description says rather than what hil simulates. So the recording gets a URDF written from
the typed description: every mesh by the absolute path hil resolved it to (``--package-path``
included), where a mesh is missing (or a box stands in for it: the link's equivalent inertia box at its
centre of mass, as the shipped seed robots have them), the link drawn as a skeleton of its
kinematics (a bone from its
origin to each child joint's, or to its centre of mass at the chain's end, and its joint
as a short cylinder along the joint's axis: a robot whose meshes are not shipped still
reads as that robot; the inertia boxes it had floated apart), mimic and corrected joints
as the plant has them.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET

import numpy as np

from hil.description import GeometryKind, Joint, Link, Pose, RobotDescription

#: joint types the viewer animates; others are fixed, as in the plant (a fixed base)
_MOVING = ("revolute", "continuous", "prismatic")
#: a skeleton's bone radius: this fraction of its length, within these bounds (m)
BONE, THINNEST, THICKEST = 0.12, 0.006, 0.03
#: bones and joints of a skeleton (RGBA)
BONE_COLOUR, JOINT_COLOUR = "0.75 0.75 0.78 1", "0.95 0.55 0.15 1"


def viewer_urdf(robot: RobotDescription) -> bytes:
    """URDF text of ``robot`` with resolved meshes (see the module's docstring)."""
    root = ET.Element("robot", name=robot.name)
    children: dict[str, list[Joint]] = {}
    parent_joint: dict[str, Joint] = {}
    for joint in robot.joints:
        children.setdefault(joint.parent, []).append(joint)
        parent_joint[joint.child] = joint
    for link in robot.links:
        root.append(_link(link, children.get(link.name, []), parent_joint.get(link.name)))
    for joint in robot.joints:
        root.append(_joint(joint))
    return ET.tostring(root, encoding="utf-8", xml_declaration=True)


def _origin(pose: Pose) -> ET.Element:
    return ET.Element("origin", xyz=" ".join(map(repr, pose.xyz)),
                      rpy=" ".join(map(repr, pose.rpy)))


def _link(link: Link, children: list[Joint], parent: Joint | None) -> ET.Element:
    element = ET.Element("link", name=link.name)
    skeleton = False                       # drawn once, however many meshes are missing
    for number, visual in enumerate(link.visuals):
        geometry = visual.geometry
        origin = visual.origin
        if geometry.kind is GeometryKind.MESH:
            shape = ET.Element("mesh", filename=str(geometry.mesh),
                               scale=" ".join(map(repr, geometry.size)))
        elif geometry.kind is GeometryKind.BOX and geometry.size and not _stand_in(link, visual):
            shape = ET.Element("box", size=" ".join(map(repr, geometry.size)))
        elif geometry.kind is GeometryKind.CYLINDER:
            shape = ET.Element("cylinder", radius=repr(geometry.size[0]),
                               length=repr(geometry.size[1]))
        elif geometry.kind is GeometryKind.SPHERE:
            shape = ET.Element("sphere", radius=repr(geometry.size[0]))
        else:                                  # a missing mesh: the kinematics' skeleton
            if not skeleton:
                element.extend(_skeleton(link, children, parent))
                skeleton = True
            continue
        drawn = ET.SubElement(element, "visual")
        drawn.append(_origin(origin))
        ET.SubElement(drawn, "geometry").append(shape)
        if visual.rgba is not None:
            material = ET.SubElement(drawn, "material", name=f"{link.name}_{number}")
            ET.SubElement(material, "color", rgba=" ".join(map(repr, visual.rgba)))
    return element


def _joint(joint: Joint) -> ET.Element:
    kind = joint.type.value if joint.type.value in _MOVING else "fixed"
    limits = joint.limits
    if kind == "revolute" and (limits is None or limits.lower is None):
        kind = "continuous"                     # hil took it as unlimited
    element = ET.Element("joint", name=joint.name, type=kind)
    ET.SubElement(element, "parent", link=joint.parent)
    ET.SubElement(element, "child", link=joint.child)
    element.append(_origin(joint.origin))
    ET.SubElement(element, "axis", xyz=" ".join(map(repr, joint.axis)))
    if kind in ("revolute", "prismatic"):
        ET.SubElement(element, "limit", lower=repr(limits.lower), upper=repr(limits.upper),
                      effort=repr(limits.effort), velocity=repr(limits.velocity))
    return element


def _skeleton(link: Link, children: list[Joint], parent: Joint | None) -> list[ET.Element]:
    """``<visual>`` elements drawing ``link`` as bones and its joint (module doc)."""
    ends = [np.array(child.origin.xyz, dtype=float) for child in children]
    if not ends and link.inertial is not None:
        ends = [np.array(link.inertial.origin.xyz, dtype=float)]
    bones = [end for end in ends if np.linalg.norm(end) > 1e-3]
    radius = max([THINNEST, *(min(THICKEST, BONE * np.linalg.norm(b)) for b in bones)])
    visuals = [_cylinder(end / 2, end, min(THICKEST, max(THINNEST, BONE * np.linalg.norm(end))),
                         np.linalg.norm(end), BONE_COLOUR, f"{link.name}_bone{k}")
               for k, end in enumerate(bones)]
    if parent is not None and parent.type.value in _MOVING:
        axis = np.array(parent.axis, dtype=float)
        visuals.append(_cylinder(np.zeros(3), axis, 1.6 * radius, 4 * radius, JOINT_COLOUR,
                                 f"{link.name}_joint"))
    return visuals


def _cylinder(centre, direction, radius: float, length: float, colour: str,
              name: str) -> ET.Element:
    """A cylinder about ``centre``, its axis along ``direction`` (URDF's: along z)."""
    x, y, z = np.asarray(direction) / np.linalg.norm(direction)
    # rpy with R z = direction: pitch about y, then yaw about z (roll 0)
    rpy = (0.0, math.acos(max(-1.0, min(1.0, z))), math.atan2(y, x))
    visual = ET.Element("visual")
    visual.append(_origin(Pose(tuple(float(c) for c in centre), rpy)))
    ET.SubElement(ET.SubElement(visual, "geometry"), "cylinder", radius=repr(float(radius)),
                  length=repr(float(length)))
    material = ET.SubElement(visual, "material", name=name)
    ET.SubElement(material, "color", rgba=colour)
    return visual


def _stand_in(link: Link, visual) -> bool:
    """Whether a box is a mesh's stand-in: the link's own equivalent inertia box at its
    centre of mass, as hil draws a missing mesh and as the shipped seed robots' descriptions
    draw theirs (their meshes are not shipped). Drawn as the skeleton instead."""
    inertial = link.inertial
    return (inertial is not None and visual.origin == inertial.origin
            and np.allclose(visual.geometry.size, inertial.equivalent_box(), rtol=2e-3))

