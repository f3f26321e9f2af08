"""Joint limits a bus config gives its robot, over the description's own.

Many public descriptions give a joint ``effort="0" velocity="0"`` (or no ``<limit>`` on a
continuous joint), which URDF readers take as "not given"; a drive is sized from both. The
config supplies them, with the key names of ros2_control's ``joint_limits.yaml``, so the
description stays the user's, untouched (``hil init`` writes them for such joints)::

    joint_limits:
      finger_joint: {max_effort: 0.5, max_velocity: 2.0}
"""

from __future__ import annotations

from dataclasses import replace

from hil.bus_config.yaml_reader import LineMapping, Reader
from hil.description import JointLimits, RobotDescription

KEYS = ("max_effort", "max_velocity")


def apply_joint_limits(reader: Reader, top: LineMapping, robot: RobotDescription
                       ) -> RobotDescription:
    """``robot`` with the config's ``joint_limits`` in place of its joints' effort and
    velocity limits; a joint that is missing or cannot move, an unknown key or a value
    that is not > 0 is reported with its line. The position range stays the description's."""
    line = top.key_lines.get("joint_limits", 1)
    entries = reader.mapping(top.get("joint_limits", LineMapping()), "'joint_limits'", line)
    movable = {j.name: j for j in robot.joints if j.is_movable}
    given = {}
    for name, raw in entries.items():
        at = entries.key_lines.get(name, line)
        what = f"joint_limits: joint '{name}'"
        joint = movable.get(name)
        if joint is None:
            why = "is not in the robot" if name not in {j.name for j in robot.joints} else \
                "cannot move"
            reader.fail(f"{what} {why}", at, hint=f"movable joints: {', '.join(movable)}")
            continue
        entry = reader.mapping(raw, what, at)
        reader.unknown_keys(entry, set(KEYS), what)
        old = joint.limits or JointLimits(lower=None, upper=None, effort=0.0, velocity=0.0)
        limits = replace(old, effort=float(reader.number(entry, "max_effort", what, old.effort)),
                         velocity=float(reader.number(entry, "max_velocity", what,
                                                      old.velocity)))
        given[name] = replace(joint, limits=limits)
    if not given:
        return robot
    return replace(robot, joints=tuple(given.get(j.name, j) for j in robot.joints))
