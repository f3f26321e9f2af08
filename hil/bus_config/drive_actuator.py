"""Which actuator a drive entry moves (named by its ``joint`` or ``actuator``), and that
actuator's software position limits on the motor side."""

from __future__ import annotations

from hil.bus_config.yaml_reader import LineMapping, Reader
from hil.description import JointType, RobotDescription
from hil.errors import did_you_mean
from hil.transmissions import SimpleTransmission, Transmission


def find_actuator(reader: Reader, drive: LineMapping, what: str, robot: RobotDescription,
                  transmissions: tuple[Transmission, ...]) -> tuple[Transmission, int] | None:
    line = drive.key_lines.get("joint", drive.key_lines.get("actuator", drive.line))
    for name_key in ("actuator", "joint"):
        if name_key in drive and not isinstance(drive[name_key], str):
            reader.fail(f"{what}: '{name_key}' must be a name, not {drive[name_key]!r}", line)
            return None
    if "actuator" in drive:
        for transmission in transmissions:
            if drive["actuator"] in transmission.actuators:
                return transmission, transmission.actuators.index(drive["actuator"])
        reader.fail(f"{what}: actuator '{drive['actuator']}' is not in robot '{robot.name}'",
                    line, hint=f"actuators: {', '.join(a.name for a in robot.actuators)}")
        return None
    joint = drive.get("joint")
    if joint is None:
        reader.fail(f"{what}: give the 'joint' (or 'actuator') this drive moves", drive.line)
        return None
    for transmission in transmissions:
        if joint in transmission.joints:
            if len(transmission.actuators) > 1:
                reader.fail(f"{what}: joint '{joint}' is driven by several actuators "
                            f"({', '.join(transmission.actuators)})", line,
                            hint="name the 'actuator' instead of the joint")
                return None
            return transmission, 0
    driven = ", ".join(j.name for j in robot.driven_joints)
    known = joint in {j.name for j in robot.joints}
    near = "" if known else did_you_mean(joint, (j.name for j in robot.driven_joints))
    reader.fail(f"{what}: joint '{joint}' " + ("has no transmission in" if known else
                                               "does not exist in") + f" robot '{robot.name}'"
                + near, line, hint=f"driven joints: {driven}")
    return None


def motor_limits(robot: RobotDescription, transmission: Transmission) -> tuple[float, float] | None:
    """Software position limits on the motor, from the joint limits (simple transmissions)."""
    if not isinstance(transmission, SimpleTransmission):
        return None
    joint = robot.joint(transmission.joints[0])
    if joint.type is JointType.CONTINUOUS or joint.limits is None or joint.limits.lower is None:
        return None
    ends = sorted(float(transmission.joint_to_actuator_position([q])[0])
                  for q in (joint.limits.lower, joint.limits.upper))
    return ends[0], ends[1]
