"""URDF element tree -> :class:`RobotDescription`, with every problem found
reported at once, each naming its file and line (transmissions:
:mod:`hil.description.urdf_transmissions`)."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections import Counter

from hil.description.corrections import (
    give_moving_links_mass, note_ignored_axes, note_world_link, physical_inertia,
)
from hil.description.model import (
    Collision, Geometry, GeometryKind, Inertial, Joint, JointDynamics, JointLimits, JointType, Link,
    Mimic, RobotDescription, TransmissionSpec, Visual,
)
from hil.description.packages import PackagePath
from hil.description.reader import ElementReader
from hil.description.source import RobotSource, first_line_of
from hil.description.urdf_checks import check_mimic, check_tree, check_visuals
from hil.description.urdf_transmissions import check_transmissions, read_transmission
from hil.errors import ConfigError, Severity, error, warning


def parse_urdf(source: RobotSource, package_path: PackagePath) -> RobotDescription:
    """Build a validated description; raise :class:`ConfigError` listing every error."""
    root = source.root
    if root.tag != "robot":
        raise ConfigError.single(f"the root element is <{root.tag}>, not <robot>", source.path,
                                 first_line_of(source.path, f"<{root.tag}"),
                                 hint="a URDF file starts with <robot name=\"...\">")
    if root.find("link") is None:
        raise ConfigError.single("the robot has no <link>: there is nothing to simulate",
                                 source.path, first_line_of(source.path, "<robot"),
                                 hint="give the robot's full description (a file of "
                                 "xacro macros alone defines no links until a macro is called)")
    reader = ElementReader(source, package_path)
    reader.diagnostics.extend(source.corrections)
    links = tuple(_read_link(reader, e) for e in root.findall("link"))
    joints = tuple(_read_joint(reader, e) for e in root.findall("joint"))
    specs = [read_transmission(reader, e) for e in root.findall("transmission")]
    for block in root.findall("ros2_control"):
        specs += [read_transmission(reader, e) for e in block.findall("transmission")]

    _check_links(reader, links)
    check_tree(reader, links, joints)
    joints = check_mimic(reader, joints)
    transmissions = check_transmissions(reader, joints, tuple(s for s in specs if s is not None))
    _check_limits(reader, joints, transmissions)
    check_visuals(reader, links, joints)
    links = give_moving_links_mass(reader, links, joints)
    note_ignored_axes(reader)
    note_world_link(reader, links, joints)

    errors = [d for d in reader.diagnostics if d.severity is Severity.ERROR]
    warnings = tuple(d for d in reader.diagnostics if d.severity is Severity.WARNING)
    if errors:
        raise ConfigError(errors + list(warnings))
    return RobotDescription(
        name=root.get("name") or source.path.stem, source=source.path, links=links,
        joints=joints, transmissions=transmissions, warnings=warnings, files=source.files)


# --- links -----------------------------------------------------------------

def _read_link(reader: ElementReader, element: ET.Element) -> Link:
    name = element.get("name", "")
    inertial = None
    found = element.find("inertial")
    if found is not None:
        inertia = found.find("inertia")
        values = {k: reader.number(inertia.get(k) if inertia is not None else None,
                                   f"link '{name}' inertia {k}", "link", name, 0.0)
                  for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")}
        mass_element = found.find("mass")
        mass = reader.number(mass_element.get("value") if mass_element is not None else None,
                             f"link '{name}' mass", "link", name, 0.0)
        inertial = Inertial(mass=mass, origin=reader.pose(found.find("origin"), "link", name),
                            **values)
        inertial, change = physical_inertia(inertial)
        if change:
            reader.report(warning, f"link '{name}' inertia is not physical for MuJoCo; corrected: "
                          f"{change}", "link", name,
                          hint="export the inertia again (kg m^2 about the centre of mass); "
                               "MuJoCo needs positive moments with A + B >= C")
    visuals = tuple(v for v in (_read_visual(reader, name, e) for e in element.findall("visual"))
                    if v is not None)
    collisions = tuple(c for c in (_read_collision(reader, name, e)
                                   for e in element.findall("collision")) if c is not None)
    return Link(name=name, inertial=inertial, visuals=visuals, collisions=collisions)


def _read_collision(reader: ElementReader, link: str, element: ET.Element) -> Collision | None:
    geometry = _read_shape(reader, link, element, "collides", "left out")
    if geometry is None:
        return None
    return Collision(origin=reader.pose(element.find("origin"), "link", link), geometry=geometry)


def _read_shape(reader: ElementReader, link: str, element: ET.Element, role: str,
                left_out: str) -> Geometry | None:
    """The geometry of a ``<visual>`` or ``<collision>``, or None (said so, with
    ``left_out``) where it has none or is a placeholder of size 0 (ROS tools draw nothing
    for it; MuJoCo refuses a geom of size 0)."""
    geometry_element = element.find("geometry")
    shape = geometry_element[0] if geometry_element is not None and len(geometry_element) else None
    if shape is None:
        reader.report(warning, f"link '{link}' has a <{element.tag}> without geometry; "
                      f"it is {left_out}", "link", link)
        return None
    geometry = _read_geometry(reader, link, shape, role)
    if geometry.kind is not GeometryKind.MESH and geometry.size and min(geometry.size) <= 0:
        reader.report(warning, f"link '{link}' has a <{element.tag}> {shape.tag} of size "
                      f"{' '.join(f'{v:g}' for v in geometry.size)}: a placeholder, {left_out}",
                      "link", link, hint=f"remove the <{element.tag}>, or give it a positive size")
        return None
    return geometry


def _read_visual(reader: ElementReader, link: str, element: ET.Element) -> Visual | None:
    geometry = _read_shape(reader, link, element, "drawn", "not drawn")
    if geometry is None:
        return None
    rgba = None
    color = element.find("material/color")
    if color is not None:
        rgba = reader.vector(color.get("rgba"), 4, f"link '{link}' rgba", "link", link,
                             (0.8, 0.8, 0.8, 1.0))
        if any(c < 0.0 or c > 1.0 for c in rgba):
            reader.report(
                warning, f"link '{link}' colour rgba=\"{color.get('rgba')}\" has components "
                "outside 0..1; they are clamped", "link", link,
                hint="URDF colours are 0..1 per channel: divide 0-255 values by 255")
            rgba = tuple(min(1.0, max(0.0, c)) for c in rgba)
    return Visual(origin=reader.pose(element.find("origin"), "link", link), geometry=geometry,
                  rgba=rgba)


def _read_geometry(reader: ElementReader, link: str, shape: ET.Element, role: str) -> Geometry:
    """The shape; ``role`` ("drawn" or "collides") words what a missing mesh becomes."""
    what = f"link '{link}' {shape.tag}"
    if shape.tag == "box":
        return Geometry(GeometryKind.BOX,
                        reader.vector(shape.get("size"), 3, f"{what} size", "link", link,
                                      (0.05,) * 3))
    if shape.tag == "cylinder":
        return Geometry(GeometryKind.CYLINDER, (
            reader.number(shape.get("radius"), f"{what} radius", "link", link, 0.02),
            reader.number(shape.get("length"), f"{what} length", "link", link, 0.05)))
    if shape.tag == "sphere":
        return Geometry(GeometryKind.SPHERE, (
            reader.number(shape.get("radius"), f"{what} radius", "link", link, 0.02),))
    if shape.tag == "mesh":
        uri = shape.get("filename", "")
        scale = reader.vector(shape.get("scale"), 3, f"{what} scale", "link", link, (1.0,) * 3)
        path = reader.find_mesh(uri)
        if path is not None:
            return Geometry(GeometryKind.MESH, scale, mesh=path)
        if uri not in reader.missing_meshes:      # a visual and a collision may share it
            reader.missing_meshes.add(uri)
            _report_missing_mesh(reader, link, uri, role)
        return Geometry(GeometryKind.BOX, (), missing_mesh=uri)
    reader.report(error, f"link '{link}' has unknown geometry <{shape.tag}>", "link", link,
                  hint="use <box>, <cylinder>, <sphere> or <mesh>")
    return Geometry(GeometryKind.BOX, (0.05,) * 3)


def _report_missing_mesh(reader: ElementReader, link: str, uri: str, role: str) -> None:
    package = uri[len("package://"):].partition("/")[0] if uri.startswith("package://") else None
    if uri in reader.refused_meshes:
        reader.report(
            warning, f"link '{link}' mesh '{uri}' not read: {reader.refused_meshes[uri]}; "
            f"{role} as a box of the link's equivalent inertia instead", "link", link,
            hint="add the mesh's folder with --package-path DIR, or keep meshes beside the "
                 "description")
    elif package and reader.package_path.find(package) is None:
        reader.report(
            warning, f"link '{link}' mesh '{uri}' not found: package '{package}' is not on "
            f"the package path ({reader.package_path.describe()}); {role} as a box of the "
            "link's equivalent inertia instead", "link", link,
            hint=f"add the folder that holds '{package}' with --package-path DIR")
    else:
        reader.report(
            warning, f"link '{link}' mesh '{uri}' not found; {role} as a box of the link's "
            "equivalent inertia instead", "link", link,
            hint="add the mesh file to its package, or use --strict to make this an error")


def _check_links(reader: ElementReader, links: tuple[Link, ...]) -> None:
    for name, count in Counter(link.name for link in links).items():
        if count > 1:
            reader.report(error, f"link name '{name}' is used {count} times", "link", name,
                          hint="link names must be unique")
    for link in links:
        if not link.name:
            reader.diagnostics.append(error("a <link> has no name", reader.source.path))
        inertial = link.inertial
        if inertial is None:
            continue
        if inertial.mass < 0:
            reader.report(error, f"link '{link.name}' has negative mass {inertial.mass}",
                          "link", link.name)


# --- joints ----------------------------------------------------------------

def _read_joint(reader: ElementReader, element: ET.Element) -> Joint:
    name = element.get("name", "")
    if not name:
        reader.diagnostics.append(error("a <joint> has no name", reader.source.path,
                                        hint="URDF names every joint"))
    type_text = element.get("type", "")
    try:
        joint_type = JointType(type_text)
    except ValueError:
        reader.report(error, f"joint '{name}' has unknown type '{type_text}'", "joint", name,
                      hint="use revolute, continuous, prismatic, fixed, floating or planar")
        joint_type = JointType.FIXED
    parent = element.find("parent")
    child = element.find("child")
    axis = reader.vector(element.find("axis").get("xyz") if element.find("axis") is not None
                         else None, 3, f"joint '{name}' axis", "joint", name, (1.0, 0.0, 0.0))
    norm = math.sqrt(sum(a * a for a in axis))
    if norm == 0.0:
        if joint_type in (JointType.REVOLUTE, JointType.CONTINUOUS, JointType.PRISMATIC,
                          JointType.PLANAR):
            reader.report(error, f"{joint_type.value} joint '{name}' has a zero axis", "joint",
                          name, hint="give <axis xyz=\"...\"> a non-zero direction")
        else:       # URDF ignores the axis of fixed and floating joints
            reader.ignored_axes.append(name)
        norm, axis = 1.0, (1.0, 0.0, 0.0)
    axis = tuple(a / norm for a in axis)
    return Joint(
        name=name, type=joint_type,
        parent=parent.get("link", "") if parent is not None else "",
        child=child.get("link", "") if child is not None else "",
        origin=reader.pose(element.find("origin"), "joint", name), axis=axis,
        limits=_read_limits(reader, name, joint_type, element.find("limit")),
        dynamics=_read_dynamics(reader, name, element.find("dynamics")),
        mimic=_read_mimic(reader, name, element.find("mimic")))


def _read_limits(reader: ElementReader, joint: str, joint_type: JointType,
                 element: ET.Element | None) -> JointLimits | None:
    if joint_type not in (JointType.REVOLUTE, JointType.PRISMATIC, JointType.CONTINUOUS):
        return None
    if element is None:
        if joint_type is JointType.CONTINUOUS:
            return None
        reader.report(error, f"{joint_type.value} joint '{joint}' has no <limit>", "joint",
                      joint, hint="add <limit lower=.. upper=.. effort=.. velocity=../>")
        return None

    def value(key: str, default: float | None) -> float | None:
        return reader.number(element.get(key), f"joint '{joint}' limit {key}", "joint", joint,
                             default)

    # a missing effort or velocity is read as 0, "not given", as pybullet and MuJoCo read it
    # (urdfdom refuses the file; `--strict` does too): _check_limits warns about it
    effort, velocity = value("effort", 0.0), value("velocity", 0.0)
    for key, amount in (("effort", effort), ("velocity", velocity)):
        if amount < 0:
            reader.report(error, f"joint '{joint}' limit {key} is {amount}; it must be >= 0",
                          "joint", joint, hint=f"give the joint's largest {key} as a positive "
                          "number")
    if joint_type is JointType.CONTINUOUS:
        lower = upper = None
    elif element.get("lower") is None and element.get("upper") is None:
        reader.report(warning, f"{joint_type.value} joint '{joint}' has no lower/upper limits "
                      "(URDF's default 0..0 would not let it move): hil takes it as unlimited",
                      "joint", joint, hint="give lower=\"..\" upper=\"..\", or make it "
                      "continuous")
        lower = upper = None
    else:
        lower, upper = value("lower", 0.0), value("upper", 0.0)
        if lower > upper:
            reader.report(error, f"joint '{joint}' limits lower={lower} > upper={upper}",
                          "joint", joint, hint="swap lower and upper")
        elif lower == upper:
            reader.report(warning, f"joint '{joint}' has lower == upper == {lower}: it cannot "
                          "move; hil takes it as unlimited (MuJoCo needs lower < upper)",
                          "joint", joint, hint="URDF defaults lower/upper to 0; give both")
            lower = upper = None
    return JointLimits(lower=lower, upper=upper, effort=effort or 0.0,
                       velocity=velocity or 0.0)


def _check_limits(reader: ElementReader, joints: tuple[Joint, ...],
                  transmissions: tuple[TransmissionSpec, ...]) -> None:
    """A joint a transmission drives needs its effort and velocity limits (the drive is
    sized from them); on a passive joint a zero limit only means 'not given'."""
    driven = {tj.name for t in transmissions for tj in t.joints}
    for joint in joints:
        limits = joint.limits
        if limits is None or not joint.is_movable:
            continue
        for key, amount in (("effort", limits.effort), ("velocity", limits.velocity)):
            if amount != 0:
                continue
            if joint.name in driven:
                reader.report(error, f"joint '{joint.name}' is driven but its limit {key} is "
                              "0 or missing", "joint", joint.name, hint=f"give <limit "
                              f"{key}=\"...\"> the joint's largest {key} (the drive is sized "
                              "from it)")
            else:
                reader.report(warning, f"joint '{joint.name}' limit {key} is 0 or missing: "
                              "taken as not given (`hil init` gives the joint hil's default "
                              "class in the bus config's joint_limits:)", "joint", joint.name,
                              hint=f"give the joint's largest {key}")


def _read_dynamics(reader: ElementReader, joint: str, element: ET.Element | None) -> JointDynamics:
    if element is None:
        return JointDynamics()
    damping = reader.number(element.get("damping"), f"joint '{joint}' damping", "joint", joint,
                            0.0)
    friction = reader.number(element.get("friction"), f"joint '{joint}' friction", "joint",
                             joint, 0.0)
    if damping < 0 or friction < 0:
        reader.report(error, f"joint '{joint}' dynamics damping={damping} friction={friction} "
                      "must not be negative", "joint", joint)
    return JointDynamics(damping=max(damping, 0.0), friction=max(friction, 0.0))


def _read_mimic(reader: ElementReader, joint: str, element: ET.Element | None) -> Mimic | None:
    if element is None:
        return None
    return Mimic(
        joint=element.get("joint", ""),
        multiplier=reader.number(element.get("multiplier"), f"joint '{joint}' mimic multiplier",
                                 "joint", joint, 1.0),
        offset=reader.number(element.get("offset"), f"joint '{joint}' mimic offset", "joint",
                             joint, 0.0))
