"""URDF ``<transmission>`` elements -> :class:`TransmissionSpec`, and their checks against
the joints (type, arity, reductions, unique names, passive joints).

Both dialects: ROS 1 ``<transmission>`` at the top level (``<type>``,
``<mechanicalReduction>``, ``<role>`` elements) and ROS 2 ``<ros2_control>`` blocks
(``<plugin>``, ``<mechanical_reduction>``, ``role`` attributes).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections import Counter, defaultdict

from hil.description.model import (
    TRANSMISSION_TYPES, Joint, TransmissionActuator, TransmissionJoint, TransmissionSpec,
)
from hil.description.reader import ElementReader
from hil.errors import error, warning

_BY_LAST_PART = {name.rpartition("/")[2]: name for name in TRANSMISSION_TYPES}
_ARITY = {"simple": 1, "differential": 2, "four_bar": 2}
#: hil's bound on a reduction's size, far beyond any drive train (a harmonic drive is
#: 30-160:1, a 0.5 mm lead screw 12,566 rad/m): past it is a typo, and 1e308 overflowed the
#: reflected inertia
MAX_REDUCTION = 1e5
#: the bound in a message's words
REDUCTION_RANGE = f"within +-{1 / MAX_REDUCTION:g} to +-{MAX_REDUCTION:g}"


def reduction_fits(value: float) -> bool:
    """Whether a reduction's size is within hil's bounds (0 is not)."""
    return 1 / MAX_REDUCTION <= abs(value) <= MAX_REDUCTION


def canonical_type(text: str) -> str:
    """ros2_control's name of a transmission type as ROS 1 or ROS 2 writes it, or ``text``
    itself where hil does not model that type."""
    return _BY_LAST_PART.get(text.strip().rpartition("/")[2], text.strip())


def read_transmission(reader: ElementReader, element: ET.Element) -> TransmissionSpec | None:
    name = element.get("name", "")
    # ROS 2: <plugin>; ROS 1: <type> or, in older files, a type="" attribute
    type_text = canonical_type(element.findtext("type") or element.findtext("plugin")
                               or element.get("type") or "")
    # older ROS 1 files give a simple transmission's reduction on the transmission itself
    shared = element.findtext("mechanicalReduction")

    def reduction_text(part: ET.Element, default: str | None = None) -> str | None:
        return (part.findtext("mechanicalReduction") or part.findtext("mechanical_reduction")
                or default)

    unreadable = [text for part, default in [(j, None) for j in element.findall("joint")]
                  + [(a, shared) for a in element.findall("actuator")]
                  if not _readable(text := reduction_text(part, default))]
    if unreadable:
        # ROS tools load such a file (the reduction is read when a controller starts): the
        # robot loads, this transmission does not, and its joint is sized as one without any
        reader.report(warning, f"transmission '{name}' has mechanical reduction "
                      f"'{unreadable[0].strip()}', which is not a number: left out, its joints "
                      "as if it had none", "transmission", name,
                      hint="a reduction is motor turns per joint turn, e.g. 100")
        return None

    def reduction(part: ET.Element, what: str, default: str | None = None) -> float:
        text = reduction_text(part, default)
        value = reader.number(text, f"transmission '{name}' {what} reduction", "transmission",
                              name, 1.0)
        if not reduction_fits(value):
            reader.report(error, f"transmission '{name}' {what} has mechanical reduction "
                          f"{value:g}, not {REDUCTION_RANGE}", "transmission", name,
                          hint="a reduction is motor turns per joint turn, e.g. 100")
            return 1.0
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
            reduction=reduction(a, f"actuator '{a.get('name')}'", shared),
            rotor_inertia=reader.number(a.findtext("rotorInertia") or a.findtext("rotor_inertia"),
                                        f"transmission '{name}' rotor inertia", "transmission",
                                        name, 0.0))
        for a in element.findall("actuator"))
    return TransmissionSpec(name=name, type=type_text, joints=_by_role(joints, "joint"),
                            actuators=_by_role(actuators, "actuator"))


def _readable(text: str | None) -> bool:
    """Whether a reduction's text is absent or a number (its value is checked later)."""
    if text is None or not text.strip():
        return True
    try:
        float(text)
    except ValueError:
        return False
    return True


def _by_role(parts: tuple, prefix: str) -> tuple:
    """Order joints/actuators by role (joint1, joint2) when roles are given."""
    if all(p.role and p.role.startswith(prefix) for p in parts):
        return tuple(sorted(parts, key=lambda p: p.role))
    return parts


def check_transmissions(reader: ElementReader, joints: tuple[Joint, ...],
                        transmissions: tuple[TransmissionSpec, ...]
                        ) -> tuple[TransmissionSpec, ...]:
    """Check every transmission against the joints; return those hil models. One of a type
    hil does not model, or on a joint that cannot have an actuator (fixed, mimic), is left
    out with a warning: its joints are passive (no actuator moves them)."""
    by_name = {j.name: j for j in joints}
    if any(count > 1 for count in Counter(t.name for t in transmissions).values()):
        # one name for several transmissions: a macro that names them all alike (the seeds'
        # defect); which actuator drives which joint cannot be told apart
        for what, named in (("transmission", [(t.name, t) for t in transmissions]),
                            ("actuator", [(a.name, t) for t in transmissions
                                          for a in t.actuators])):
            _check_unique(reader, what, named, hint="give each its own name, e.g. in a macro "
                          f"name=\"${{joint_name}}_{'trans' if what == 'transmission' else 'motor'}\"")
        return ()
    transmissions = _first_of_each(reader, transmissions)
    kept = []
    for spec in transmissions:
        kind = TRANSMISSION_TYPES.get(spec.type)
        if kind is None:
            reader.report(warning, f"transmission '{spec.name}' has type '{spec.type}', which "
                          "hil does not model: left out, its joints "
                          f"({', '.join(j.name for j in spec.joints)}) are passive",
                          "transmission", spec.name,
                          hint=f"hil models: {', '.join(TRANSMISSION_TYPES)}")
            continue
        if _unactuatable(reader, spec, by_name):
            continue
        arity = _ARITY[kind]
        if len(spec.joints) != arity or len(spec.actuators) != arity:
            reader.report(error, f"transmission '{spec.name}' ({kind}) has "
                          f"{len(spec.joints)} joint(s) and {len(spec.actuators)} actuator(s); "
                          f"it needs {arity} of each", "transmission", spec.name,
                          hint=f"give it {arity} <joint> and {arity} <actuator> elements")
        for actuator in spec.actuators:
            if actuator.rotor_inertia < 0:
                reader.report(error, f"actuator '{actuator.name}' has negative rotor inertia",
                              "transmission", spec.name,
                              hint="give the rotor's inertia in kg m^2 (>= 0)")
        kept.append(spec)
    return tuple(kept)


def _unactuatable(reader: ElementReader, spec: TransmissionSpec,
                  by_name: dict[str, Joint]) -> bool:
    """Report a transmission that cannot act (on a missing, fixed or mimic joint); True if
    it is to be left out."""
    for tj in spec.joints:
        joint = by_name.get(tj.name)
        if joint is None:
            movable = ", ".join(name for name, j in by_name.items() if j.is_movable)
            reader.report(warning, f"transmission '{spec.name}' names joint '{tj.name}', "
                          "which does not exist: left out", "transmission", spec.name,
                          hint=f"name one of: {movable}")
            return True
        if not joint.is_movable or joint.mimic is not None:
            why = (f"{joint.type.value} joint '{tj.name}', which cannot move"
                   if not joint.is_movable else
                   f"mimic joint '{tj.name}', which follows its leader")
            reader.report(warning, f"transmission '{spec.name}' drives {why}: left out",
                          "transmission", spec.name,
                          hint="remove the transmission, or the joint's <mimic>/fixed type")
            return True
    return False


def _first_of_each(reader: ElementReader, transmissions: tuple[TransmissionSpec, ...]
                   ) -> tuple[TransmissionSpec, ...]:
    """Each actuator and each joint in one transmission: the first that names it is kept,
    a later one is left out with a warning (an underactuated hand's one motor for several
    fingers is written so; hil drives the first finger and the others are passive)."""
    kept: list[TransmissionSpec] = []
    owner: dict[tuple[str, str], str] = {}
    for spec in transmissions:
        taken = [(what, name) for what, name in
                 [*(("actuator", a.name) for a in spec.actuators),
                  *(("joint", j.name) for j in spec.joints)] if (what, name) in owner]
        if taken:
            what, name = taken[0]
            reader.report(warning, f"transmission '{spec.name}' names {what} '{name}', which "
                          f"transmission '{owner[what, name]}' already drives: left out",
                          "transmission", spec.name,
                          hint=f"a {what} belongs to one transmission; give this one its own")
            continue
        for part in spec.actuators:
            owner["actuator", part.name] = spec.name
        for part in spec.joints:
            owner["joint", part.name] = spec.name
        kept.append(spec)
    return tuple(kept)


def _check_unique(reader: ElementReader, what: str, named: list[tuple[str, TransmissionSpec]],
                  hint: str) -> None:
    users: dict[str, list[str]] = defaultdict(list)
    for name, spec in named:
        users[name].append(", ".join(j.name for j in spec.joints))
    for name, joint_lists in users.items():
        if len(joint_lists) > 1:
            reader.report(error, f"{what} name '{name}' is used by {len(joint_lists)} "
                          f"transmissions (joints {'; '.join(joint_lists)})", what, name,
                          hint=hint)
