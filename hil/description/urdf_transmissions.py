"""URDF ``<transmission>`` elements -> :class:`TransmissionSpec`, and their checks against
the joints (type, arity, reductions, unique names, passive joints).

Both dialects: ROS 1 ``<transmission>`` at the top level (``<type>``,
``<mechanicalReduction>``, ``<role>`` elements) and ROS 2 ``<ros2_control>`` blocks
(``<plugin>``, ``<mechanical_reduction>``, ``role`` attributes).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections import defaultdict

from hil.description.model import (
    Joint, TransmissionActuator, TransmissionJoint, TransmissionSpec,
)
from hil.description.reader import ElementReader
from hil.errors import error, warning

#: Transmission types hil can model, by the names ROS 1 and ROS 2 use for them.
TRANSMISSION_TYPES = {
    "transmission_interface/SimpleTransmission": "simple",
    "transmission_interface/DifferentialTransmission": "differential",
    "transmission_interface/FourBarLinkageTransmission": "four_bar",
}
_ARITY = {"simple": 1, "differential": 2, "four_bar": 2}



def read_transmission(reader: ElementReader, element: ET.Element) -> TransmissionSpec | None:
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


def check_transmissions(reader: ElementReader, joints: tuple[Joint, ...],
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


def _check_simple_reduction(reader: ElementReader, spec: TransmissionSpec) -> None:
    # Coupled transmissions use signs for their direction conventions (as in
    # ros2_control); a simple one has the joint axis for that.
    for part in (*spec.joints, *spec.actuators):
        if part.reduction < 0:
            reader.report(error, f"transmission '{spec.name}' has mechanical reduction "
                          f"{part.reduction} on '{part.name}'; it must be > 0", "transmission",
                          spec.name, hint="to reverse the direction, flip the joint's <axis>")


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
