"""Transmissions a bus config adds to its robot, for joints the description leaves passive.

Most public descriptions have no ``<transmission>``; ``hil init`` writes them into the bus
config instead, so the description stays the user's, untouched. One simple transmission
per joint, named ``<joint>_transmission`` with actuator ``<joint>_motor``::

    transmissions:
      shoulder_pan_joint: {reduction: 100, rotor_inertia: 3.3e-5}
"""

from __future__ import annotations

from dataclasses import replace

from hil.bus_config.yaml_reader import LineMapping, Reader
from hil.description import (
    RobotDescription, TransmissionActuator, TransmissionJoint, TransmissionSpec,
)
from hil.description.urdf_transmissions import REDUCTION_RANGE, reduction_fits

_KEYS = {"reduction", "rotor_inertia", "offset"}
#: hil's bound on a rotor's inertia, far beyond any servo's (a large one's is 0.01 kg m^2)
MAX_ROTOR_INERTIA = 100.0
SIMPLE = "transmission_interface/SimpleTransmission"


def actuator_of(joint: str) -> str:
    """The name of the actuator a config transmission gives ``joint``."""
    return f"{joint}_motor"


def add_transmissions(reader: Reader, top: LineMapping, robot: RobotDescription
                      ) -> RobotDescription:
    """``robot`` with the config's ``transmissions`` added; each problem is reported with
    its line (a joint that is missing, cannot move, follows a mimic or is driven already;
    a zero reduction; a limit the drive would be sized from that is not given)."""
    line = top.key_lines.get("transmissions", 1)
    entries = reader.mapping(top.get("transmissions", LineMapping()), "'transmissions'", line)
    driven = {tj.name: t.name for t in robot.transmissions for tj in t.joints}
    joints = {j.name: j for j in robot.joints}
    added = []
    for name, raw in entries.items():
        at = entries.key_lines.get(name, line)
        what = f"transmissions: joint '{name}'"
        joint = joints.get(name)
        if joint is None or not joint.is_movable or joint.mimic is not None:
            why = ("is not in the robot" if joint is None else
                   f"is {joint.type.value} and cannot move" if not joint.is_movable else
                   f"follows '{joint.mimic.joint}' (mimic)")
            movable = [j.name for j in robot.joints if j.is_movable and j.mimic is None]
            reader.fail(f"{what} {why}", at, hint=f"movable joints: {', '.join(movable)}")
            continue
        if name in driven:
            reader.fail(f"{what} is driven by the description's transmission "
                        f"'{driven[name]}' already", at,
                        hint="remove it here, or the <transmission> from the description")
            continue
        for key, amount in (("effort", joint.limits.effort), ("velocity", joint.limits.velocity)):
            if amount <= 0:
                reader.fail(f"{what}: the description gives no {key} limit, which the drive is "
                            "sized from", at, hint=f"give it max_{key} under 'joint_limits:' here, "
                            f"or the joint <limit {key}=\"...\">")
        entry = reader.mapping(raw, what, at)
        reader.unknown_keys(entry, _KEYS, what)
        reduction = reader.number(entry, "reduction", what, positive=False)
        if not reduction_fits(reduction):
            reader.fail(f"{what}: 'reduction' {reduction:g} is not {REDUCTION_RANGE}",
                        entry.key_lines.get("reduction", at),
                        hint="motor turns per joint turn (rad per m for a prismatic joint)")
            reduction = 1.0
        rotor = reader.number(entry, "rotor_inertia", what, 0.0, positive=False)
        if not 0 <= rotor <= MAX_ROTOR_INERTIA:
            reader.fail(f"{what}: 'rotor_inertia' must be 0 to {MAX_ROTOR_INERTIA:g} (kg m^2)",
                        entry.key_lines.get("rotor_inertia", at))
            rotor = 0.0
        added.append(TransmissionSpec(
            name=f"{name}_transmission", type=SIMPLE,
            joints=(TransmissionJoint(name=name, offset=float(reader.number(
                entry, "offset", what, 0.0, positive=False))),),
            actuators=(TransmissionActuator(name=actuator_of(name), reduction=float(reduction),
                                            rotor_inertia=float(rotor)),)))
    robot = replace(robot, transmissions=robot.transmissions + tuple(added))
    driven = {tj.name for t in robot.transmissions for tj in t.joints}
    passive = [j.name for j in robot.joints
               if j.is_movable and j.mimic is None and j.name not in driven]
    if passive:
        reader.warn(f"{len(passive)} joint(s) of '{robot.name}' have no transmission and are "
                    f"passive (no drive moves them): {', '.join(passive)}", line,
                    hint="give them 'transmissions:' here (`hil init` writes them) or "
                         "<transmission> elements in the description")
    return robot
