"""The robot as rerun's URDF loader is to draw it, written from hil's description.

rerun finds ``package://`` meshes through ``ROS_PACKAGE_PATH`` only, and would draw what the
description says rather than what hil simulates. So the recording gets a URDF written from
the typed description: every mesh by the absolute path hil resolved it to (``--package-path``
included), a box of the link's equivalent inertia where a mesh is missing (as the plant
draws it), mimic and corrected joints as the plant has them.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

from hil.description import GeometryKind, Joint, Link, Pose, RobotDescription

#: joint types the viewer animates; others are fixed, as in the plant (a fixed base)
_MOVING = ("revolute", "continuous", "prismatic")


def viewer_urdf(robot: RobotDescription) -> bytes:
    """URDF text of ``robot`` with resolved meshes (see the module's docstring)."""
    root = ET.Element("robot", name=robot.name)
    for link in robot.links:
        root.append(_link(link))
    for joint in robot.joints:
        root.append(_joint(joint))
    return ET.tostring(root, encoding="utf-8", xml_declaration=True)


def _origin(pose: Pose) -> ET.Element:
    return ET.Element("origin", xyz=" ".join(map(repr, pose.xyz)),
                      rpy=" ".join(map(repr, pose.rpy)))


def _link(link: Link) -> ET.Element:
    element = ET.Element("link", name=link.name)
    for number, visual in enumerate(link.visuals):
        geometry = visual.geometry
        origin = visual.origin
        if geometry.kind is GeometryKind.MESH:
            shape = ET.Element("mesh", filename=str(geometry.mesh),
                               scale=" ".join(map(repr, geometry.size)))
        elif geometry.kind is GeometryKind.BOX and geometry.size:
            shape = ET.Element("box", size=" ".join(map(repr, geometry.size)))
        elif geometry.kind is GeometryKind.CYLINDER:
            shape = ET.Element("cylinder", radius=repr(geometry.size[0]),
                               length=repr(geometry.size[1]))
        elif geometry.kind is GeometryKind.SPHERE:
            shape = ET.Element("sphere", radius=repr(geometry.size[0]))
        elif link.inertial is not None:        # a missing mesh: the plant's box
            shape = ET.Element("box", size=" ".join(map(repr, link.inertial.equivalent_box())))
            origin = link.inertial.origin
        else:
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
