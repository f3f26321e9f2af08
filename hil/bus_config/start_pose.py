"""The bus config's ``start_pose:``: where joints are when the plant starts (the robot's
power-on pose), over hil's own choice (every joint at zero, or just inside a range that
excludes zero)::

    start_pose:
      FR_thigh_joint: 0.62
      FR_calf_joint: -1.24

``hil init`` writes one for a robot that stands (each foot under its hip).
"""

from __future__ import annotations

from hil.bus_config.yaml_reader import LineMapping, Reader
from hil.description import RobotDescription


def read_start_pose(reader: Reader, top: LineMapping, robot: RobotDescription
                    ) -> tuple[tuple[str, float], ...]:
    """The ``start_pose:`` entries, (joint, position) in the file's order; a joint that is
    missing, cannot move or mimics another, or a position outside its limits, is reported
    with its line."""
    line = top.key_lines.get("start_pose", 1)
    entries = reader.mapping(top.get("start_pose", LineMapping()), "'start_pose'", line)
    movable = {j.name: j for j in robot.joints if j.is_movable and j.mimic is None}
    pose = []
    for name in entries:
        at = entries.key_lines.get(name, line)
        what = f"start_pose: joint '{name}'"
        joint = movable.get(name)
        if joint is None:
            why = ("is not in the robot" if name not in {j.name for j in robot.joints} else
                   "follows another joint (mimic): it starts where its leader puts it"
                   if any(j.name == name and j.mimic for j in robot.joints) else "cannot move")
            reader.fail(f"{what} {why}", at, hint=f"joints that can start anywhere: "
                                                  f"{', '.join(movable)}")
            continue
        value = reader.number(entries, name, what, None, positive=False)
        limits = joint.limits
        if limits is not None and limits.lower is not None and not (
                limits.lower <= value <= limits.upper):
            reader.fail(f"{what}: {value:g} is outside its limits [{limits.lower:g}, "
                        f"{limits.upper:g}]", at, hint="a drive faults on a limit it starts "
                                                       "beyond: give a position inside them")
            continue
        pose.append((name, float(value)))
    return tuple(pose)
