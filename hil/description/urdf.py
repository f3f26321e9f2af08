"""URDF element tree -> :class:`RobotDescription`, with every problem found
reported at once, each naming its file and line.

Transmissions are read in both dialects: ROS 1 ``<transmission>`` at the top
level (``<type>``, ``<mechanicalReduction>``, ``<role>`` elements) and ROS 2
``<ros2_control>`` blocks (``<plugin>``, ``<mechanical_reduction>``, ``role``
attributes).
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from collections import Counter, defaultdict
from pathlib import Path

from hil.description.model import (
    Geometry, GeometryKind, Inertial, Joint, JointDynamics, JointLimits, JointType, Link,
    Mimic, Pose, RobotDescription, TransmissionActuator, TransmissionJoint, TransmissionSpec,
    Visual,
)
from hil.description.packages import PackagePath
from hil.description.source import RobotSource
from hil.errors import Diagnostic, HilError, Severity, error, warning

#: Transmission types hil can model, by the names ROS 1 and ROS 2 use for them.
TRANSMISSION_TYPES = {
    "transmission_interface/SimpleTransmission": "simple",
    "transmission_interface/DifferentialTransmission": "differential",
    "transmission_interface/FourBarLinkageTransmission": "four_bar",
}
_ARITY = {"simple": 1, "differential": 2, "four_bar": 2}


def start_tag(tag: str, name: str) -> re.Pattern:
    """The start tag ``<tag ... name="name"``, across lines and other attributes."""
    return re.compile(rf"<{re.escape(tag)}\b[^>]*?\bname\s*=\s*[\"']{re.escape(name)}[\"']",
                      re.DOTALL)


class SourceIndex:
    """Finds the file and line where a named element is written.

    The expanded URDF has no line numbers (xacro builds it in memory), so an
    element is found by searching the source files for its start tag with
    the same ``name``. Names built by macros (``${prefix}joint``) are not
    found; the diagnostic then names the top-level file only.
    """

    def __init__(self, files: tuple[Path, ...]):
        self.files = files
        self._texts = {f: f.read_text(errors="replace") for f in files if f.is_file()}

    def locate(self, tag: str, name: str) -> tuple[Path, int | None]:
        pattern = start_tag(tag, name)
        for file, text in self._texts.items():
            match = pattern.search(text)
            if match:
                return file, text.count("\n", 0, match.start()) + 1
        return self.files[0], None


class _Reader:
    """One pass over a URDF tree, collecting diagnostics instead of stopping."""

    def __init__(self, source: RobotSource, package_path: PackagePath):
        self.source = source
        self.package_path = package_path
        self.index = SourceIndex(source.files)
        self.diagnostics: list[Diagnostic] = []

    def report(self, make, message: str, tag: str, name: str, hint: str | None = None) -> None:
        file, line = self.index.locate(tag, name)
        self.diagnostics.append(make(message, file, line, hint))

    def number(self, text: str | None, what: str, tag: str, name: str,
               default: float | None = None) -> float | None:
        if text is None or text.strip() == "":
            return default
        try:
            value = float(text)
        except ValueError:
            self.report(error, f"{what} '{text}' is not a number", tag, name,
                        hint="write a plain decimal number (xacro expressions need ${...})")
            return default
        if not math.isfinite(value):
            self.report(error, f"{what} is {value}", tag, name, hint="use a finite number")
            return default
        return value

    def vector(self, text: str | None, size: int, what: str, tag: str, name: str,
               default: tuple[float, ...]) -> tuple[float, ...]:
        if text is None:
            return default
        parts = text.split()
        values = [self.number(p, what, tag, name) for p in parts]
        if len(parts) != size or any(v is None for v in values):
            if len(parts) != size:
                self.report(error, f"{what} '{text}' needs {size} numbers", tag, name)
            return default
        return tuple(values)

    def pose(self, element: ET.Element | None, tag: str, name: str) -> Pose:
        if element is None:
            return Pose()
        return Pose(self.vector(element.get("xyz"), 3, "origin xyz", tag, name, (0.0,) * 3),
                    self.vector(element.get("rpy"), 3, "origin rpy", tag, name, (0.0,) * 3))


def parse_urdf(source: RobotSource, package_path: PackagePath) -> RobotDescription:
    """Build a validated description; raise :class:`HilError` listing every error."""
    root = source.root
    if root.tag != "robot":
        raise HilError.single(f"the root element is <{root.tag}>, not <robot>", source.path,
                              hint="a URDF file starts with <robot name=\"...\">")
    reader = _Reader(source, package_path)
    links = tuple(_read_link(reader, e) for e in root.findall("link"))
    joints = tuple(_read_joint(reader, e) for e in root.findall("joint"))
    specs = [_read_transmission(reader, e) for e in root.findall("transmission")]
    for block in root.findall("ros2_control"):
        specs += [_read_transmission(reader, e) for e in block.findall("transmission")]
    transmissions = tuple(s for s in specs if s is not None)

    _check_links(reader, links)
    _check_tree(reader, links, joints)
    _check_mimic(reader, joints)
    _check_transmissions(reader, joints, transmissions)
    _check_visuals(reader, links, joints)

    errors = [d for d in reader.diagnostics if d.severity is Severity.ERROR]
    warnings = tuple(d for d in reader.diagnostics if d.severity is Severity.WARNING)
    if errors:
        raise HilError(errors + list(warnings))
    return RobotDescription(
        name=root.get("name") or source.path.stem, source=source.path, links=links,
        joints=joints, transmissions=transmissions, warnings=warnings)


# --- links -----------------------------------------------------------------

def _read_link(reader: _Reader, element: ET.Element) -> Link:
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
    visuals = tuple(v for v in (_read_visual(reader, name, e) for e in element.findall("visual"))
                    if v is not None)
    return Link(name=name, inertial=inertial, visuals=visuals)


def _read_visual(reader: _Reader, link: str, element: ET.Element) -> Visual | None:
    geometry_element = element.find("geometry")
    shape = geometry_element[0] if geometry_element is not None and len(geometry_element) else None
    if shape is None:
        reader.report(warning, f"link '{link}' has a <visual> without geometry; it is not drawn",
                      "link", link)
        return None
    geometry = _read_geometry(reader, link, shape)
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


def _read_geometry(reader: _Reader, link: str, shape: ET.Element) -> Geometry:
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
        path = resolve_uri(uri, reader.source.path, reader.package_path)
        if path is not None and path.is_file():
            return Geometry(GeometryKind.MESH, scale, mesh=path)
        reader.report(
            warning, f"link '{link}' mesh '{uri}' not found; drawn as a box of the link's "
            "equivalent inertia instead", "link", link,
            hint="add the mesh file to its package, or use --strict to make this an error")
        return Geometry(GeometryKind.BOX, (), missing_mesh=uri)
    reader.report(error, f"link '{link}' has unknown geometry <{shape.tag}>", "link", link,
                  hint="use <box>, <cylinder>, <sphere> or <mesh>")
    return Geometry(GeometryKind.BOX, (0.05,) * 3)


def resolve_uri(uri: str, relative_to: Path, package_path: PackagePath) -> Path | None:
    """``package://pkg/rel``, ``file:///abs`` or a path relative to the URDF file."""
    if uri.startswith("package://"):
        package, _, rest = uri[len("package://"):].partition("/")
        folder = package_path.find(package)
        return folder / rest if folder else None
    if uri.startswith("file://"):
        return Path(uri[len("file://"):])
    return relative_to.parent / uri


def _check_links(reader: _Reader, links: tuple[Link, ...]) -> None:
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
        principal = (inertial.ixx, inertial.iyy, inertial.izz)
        if any(i < 0 for i in principal) or any(
                principal[a] + principal[b] < principal[c] * (1 - 1e-6)
                for a, b, c in ((0, 1, 2), (1, 2, 0), (2, 0, 1))):
            reader.report(error, f"link '{link.name}' inertia (ixx, iyy, izz) = {principal} "
                          "is not physical (each must be >= 0 and no one larger than the sum "
                          "of the other two)", "link", link.name,
                          hint="check the inertia export (units kg m^2, about the centre of mass)")


# --- joints ----------------------------------------------------------------

def _read_joint(reader: _Reader, element: ET.Element) -> Joint:
    name = element.get("name", "")
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
        reader.report(error, f"joint '{name}' has a zero axis", "joint", name,
                      hint="give <axis xyz=\"...\"> a non-zero direction")
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


def _read_limits(reader: _Reader, joint: str, joint_type: JointType,
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

    effort, velocity = value("effort", None), value("velocity", None)
    for key, amount in (("effort", effort), ("velocity", velocity)):
        if amount is None:
            reader.report(error, f"joint '{joint}' <limit> has no {key}", "joint", joint,
                          hint=f"URDF requires {key}=\"...\" on every <limit>")
        elif amount <= 0:
            reader.report(error, f"joint '{joint}' limit {key} is {amount}; it must be > 0",
                          "joint", joint)
    if joint_type is JointType.CONTINUOUS:
        lower = upper = None
    else:
        lower, upper = value("lower", 0.0), value("upper", 0.0)
        if lower > upper:
            reader.report(error, f"joint '{joint}' limits lower={lower} > upper={upper}",
                          "joint", joint, hint="swap lower and upper")
        elif lower == upper:
            reader.report(warning, f"joint '{joint}' has lower == upper == {lower}: it cannot "
                          "move", "joint", joint,
                          hint="URDF defaults lower/upper to 0; give both")
    return JointLimits(lower=lower, upper=upper, effort=effort or 0.0,
                       velocity=velocity or 0.0)


def _read_dynamics(reader: _Reader, joint: str, element: ET.Element | None) -> JointDynamics:
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


def _read_mimic(reader: _Reader, joint: str, element: ET.Element | None) -> Mimic | None:
    if element is None:
        return None
    return Mimic(
        joint=element.get("joint", ""),
        multiplier=reader.number(element.get("multiplier"), f"joint '{joint}' mimic multiplier",
                                 "joint", joint, 1.0),
        offset=reader.number(element.get("offset"), f"joint '{joint}' mimic offset", "joint",
                             joint, 0.0))


def _check_tree(reader: _Reader, links: tuple[Link, ...], joints: tuple[Joint, ...]) -> None:
    link_names = {link.name for link in links}
    for name, count in Counter(j.name for j in joints).items():
        if count > 1:
            reader.report(error, f"joint name '{name}' is used {count} times", "joint", name,
                          hint="joint names must be unique")
    parents_of: dict[str, list[str]] = defaultdict(list)
    for joint in joints:
        for role, link in (("parent", joint.parent), ("child", joint.child)):
            if not link:
                reader.report(error, f"joint '{joint.name}' has no <{role} link=...>", "joint",
                              joint.name)
            elif link not in link_names:
                reader.report(error, f"joint '{joint.name}': {role} link '{link}' is not "
                              "defined in any loaded file", "joint", joint.name,
                              hint=_missing_link_hint(reader, link))
        parents_of[joint.child].append(joint.name)
    for child, names in parents_of.items():
        if len(names) > 1:
            reader.report(error, f"link '{child}' is the child of several joints "
                          f"({', '.join(names)}); URDF needs a tree", "link", child)
    roots = [link.name for link in links if link.name not in parents_of]
    dangling = any(j.parent not in link_names for j in joints)
    if links and not roots and not dangling:
        reader.diagnostics.append(error("the joints form a loop: no link is a root",
                                        reader.source.path))
    elif len(roots) > 1:
        reader.diagnostics.append(error(
            f"the robot has {len(roots)} unconnected root links ({', '.join(roots)})",
            reader.source.path, hint="connect every link to one tree with joints"))


def _missing_link_hint(reader: _Reader, link: str) -> str:
    """Name the file that defines ``link`` if it lies on the package path unincluded."""
    pattern = start_tag("link", link)
    loaded = set(reader.source.files)
    for root in reader.package_path.roots:
        if not root.is_dir():
            continue
        for candidate in sorted(root.rglob("*")):
            if candidate.suffix not in (".xacro", ".urdf") or candidate.resolve() in loaded:
                continue
            if pattern.search(candidate.read_text(errors="replace")):
                return (f"'{link}' is defined in {candidate}, which is not included: add "
                        f"<xacro:include filename=\"{_find_form(candidate, reader.package_path)}\"/>")
    return (f"define <link name=\"{link}\"/> or include the file that defines it "
            "(no file on the package search path does)")


def _find_form(file: Path, package_path: PackagePath) -> str:
    """``$(find pkg)/rel`` for a file inside a package on the path, else the plain path."""
    for name, folder in package_path.packages().items():
        if file.resolve().is_relative_to(folder.resolve()):
            return f"$(find {name})/{file.resolve().relative_to(folder.resolve())}"
    return str(file)


def _check_mimic(reader: _Reader, joints: tuple[Joint, ...]) -> None:
    by_name = {j.name: j for j in joints}
    for joint in joints:
        if joint.mimic is None:
            continue
        leader = by_name.get(joint.mimic.joint)
        if leader is None:
            reader.report(error, f"joint '{joint.name}' mimics joint '{joint.mimic.joint}', "
                          "which does not exist", "joint", joint.name,
                          hint=f"name one of: {', '.join(j.name for j in joints if j.is_movable)}")
        elif leader.name == joint.name or leader.mimic is not None:
            reader.report(error, f"joint '{joint.name}' mimics '{leader.name}', which is itself "
                          "or a mimic joint", "joint", joint.name,
                          hint="mimic an actuated joint directly")


# --- transmissions ---------------------------------------------------------

def _read_transmission(reader: _Reader, element: ET.Element) -> TransmissionSpec | None:
    name = element.get("name", "")
    type_text = (element.findtext("type") or element.findtext("plugin") or "").strip()

    def reduction(part: ET.Element, what: str) -> float:
        text = part.findtext("mechanicalReduction") or part.findtext("mechanical_reduction")
        value = reader.number(text, f"transmission '{name}' {what} reduction", "transmission",
                              name, 1.0)
        if value == 0:
            reader.report(error, f"transmission '{name}' {what} has mechanical reduction 0",
                          "transmission", name,
                          hint="a reduction is motor turns per joint turn, e.g. 100")
        return value

    def role(part: ET.Element) -> str | None:
        return part.get("role") or (part.findtext("role") or "").strip() or None

    joints = tuple(
        TransmissionJoint(name=j.get("name", ""), role=role(j),
                          reduction=reduction(j, f"joint '{j.get('name')}'"),
                          offset=reader.number(j.findtext("offset"),
                                               f"transmission '{name}' offset", "transmission",
                                               name, 0.0))
        for j in element.findall("joint"))
    actuators = tuple(
        TransmissionActuator(
            name=a.get("name", ""), role=role(a),
            reduction=reduction(a, f"actuator '{a.get('name')}'"),
            rotor_inertia=reader.number(a.findtext("rotorInertia") or a.findtext("rotor_inertia"),
                                        f"transmission '{name}' rotor inertia", "transmission",
                                        name, 0.0))
        for a in element.findall("actuator"))
    return TransmissionSpec(name=name, type=type_text, joints=_by_role(joints, "joint"),
                            actuators=_by_role(actuators, "actuator"))


def _by_role(parts: tuple, prefix: str) -> tuple:
    """Order joints/actuators by role (joint1, joint2) when roles are given."""
    if all(p.role and p.role.startswith(prefix) for p in parts):
        return tuple(sorted(parts, key=lambda p: p.role))
    return parts


def _check_transmissions(reader: _Reader, joints: tuple[Joint, ...],
                         transmissions: tuple[TransmissionSpec, ...]) -> None:
    by_name = {j.name: j for j in joints}
    _check_unique(reader, "transmission", [(t.name, t) for t in transmissions],
                  hint="give each transmission its own name, e.g. in a macro "
                       "name=\"${joint_name}_trans\"")
    _check_unique(reader, "actuator", [(a.name, t) for t in transmissions for a in t.actuators],
                  hint="each actuator drives through one transmission: give each its own "
                       "name, e.g. name=\"${joint_name}_motor\"")
    _check_unique(reader, "joint", [(j.name, t) for t in transmissions for j in t.joints],
                  hint="a joint can be driven through one transmission only")
    for spec in transmissions:
        kind = TRANSMISSION_TYPES.get(spec.type)
        if kind is None:
            reader.report(error, f"transmission '{spec.name}' has unknown type '{spec.type}'",
                          "transmission", spec.name,
                          hint=f"use one of: {', '.join(TRANSMISSION_TYPES)}")
            continue
        if kind == "simple":
            _check_simple_reduction(reader, spec)
        arity = _ARITY[kind]
        if len(spec.joints) != arity or len(spec.actuators) != arity:
            reader.report(error, f"transmission '{spec.name}' ({kind}) has "
                          f"{len(spec.joints)} joint(s) and {len(spec.actuators)} actuator(s); "
                          f"it needs {arity} of each", "transmission", spec.name)
        for tj in spec.joints:
            joint = by_name.get(tj.name)
            if joint is None:
                reader.report(error, f"transmission '{spec.name}' names joint '{tj.name}', "
                              "which does not exist", "transmission", spec.name,
                              hint=f"name one of: {', '.join(j.name for j in joints if j.is_movable)}")
            elif not joint.is_movable:
                reader.report(error, f"transmission '{spec.name}' drives {joint.type.value} "
                              f"joint '{tj.name}', which cannot move", "transmission", spec.name)
            elif joint.mimic is not None:
                reader.report(error, f"transmission '{spec.name}' drives mimic joint "
                              f"'{tj.name}'; a mimic joint follows its leader and has no "
                              "actuator", "transmission", spec.name,
                              hint="remove the transmission or the <mimic>")
        for actuator in spec.actuators:
            if actuator.rotor_inertia < 0:
                reader.report(error, f"actuator '{actuator.name}' has negative rotor inertia",
                              "transmission", spec.name)
    driven = {tj.name for t in transmissions for tj in t.joints}
    for joint in joints:
        if joint.is_movable and joint.mimic is None and joint.name not in driven:
            reader.report(warning, f"joint '{joint.name}' has no transmission: it is passive "
                          "(no actuator moves it)", "joint", joint.name,
                          hint="add a <transmission> if a motor drives this joint")


def _check_simple_reduction(reader: _Reader, spec: TransmissionSpec) -> None:
    # Coupled transmissions use signs for their direction conventions (as in
    # ros2_control); a simple one has the joint axis for that.
    for part in (*spec.joints, *spec.actuators):
        if part.reduction < 0:
            reader.report(error, f"transmission '{spec.name}' has mechanical reduction "
                          f"{part.reduction} on '{part.name}'; it must be > 0", "transmission",
                          spec.name, hint="to reverse the direction, flip the joint's <axis>")


def _check_unique(reader: _Reader, what: str, named: list[tuple[str, TransmissionSpec]],
                  hint: str) -> None:
    users: dict[str, list[str]] = defaultdict(list)
    for name, spec in named:
        users[name].append(", ".join(j.name for j in spec.joints))
    for name, joint_lists in users.items():
        if len(joint_lists) > 1:
            reader.report(error, f"{what} name '{name}' is used by {len(joint_lists)} "
                          f"transmissions (joints {'; '.join(joint_lists)})", what, name,
                          hint=hint)


# --- visuals ---------------------------------------------------------------

def _check_visuals(reader: _Reader, links: tuple[Link, ...], joints: tuple[Joint, ...]) -> None:
    """Warn about visuals far outside the robot (unit or export errors)."""
    extent = sum(j.origin.distance for j in joints)
    limit = max(1.0, 2.0 * extent)
    for link in links:
        for visual in link.visuals:
            if visual.origin.distance > limit:
                reader.report(
                    warning, f"link '{link.name}' visual origin is {visual.origin.distance:.1f} m "
                    f"from the link frame, but the whole robot spans about {extent:.2f} m",
                    "link", link.name,
                    hint="check the <visual><origin xyz=...> (a unit or export error?); "
                         "it is drawn where it says")
