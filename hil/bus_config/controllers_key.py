"""The bus config's ``controllers:``: the user's own controller_manager YAML (a
ros2_controllers.yaml, as their bringup or MoveIt config has it), how its names meet this
bench's joints, and which of its controllers run from the start::

    controllers:
      file: ur_controllers.yaml          # relative to the bus config
      joint_names: {shoulder_pan_joint: joint1, shoulder_lift_joint: joint2}
      vars: {tf_prefix: ""}              # the file's $(var NAME) launch arguments
      active: [joint_trajectory_controller]

The file itself is read by :mod:`hil.controllers.config` (the controllers' stage)."""

from __future__ import annotations

import re

from hil.bus_config.types import ControllersSource
from hil.bus_config.yaml_reader import LineMapping, Reader

_KEYS = {"file", "joint_names", "vars", "active"}
#: a $(var NAME) value is put into the file's text: a plain name, path or number, so that
#: it cannot change the YAML's structure
VAR_VALUE = re.compile(r"[A-Za-z0-9_./:-]*")


def read_controllers(reader: Reader, top: LineMapping) -> ControllersSource | None:
    """The ``controllers:`` entry, or None without one; problems reported with their lines."""
    if "controllers" not in top:
        return None
    line = top.key_lines.get("controllers", 1)
    entry = reader.mapping(top["controllers"], "'controllers'", line)
    reader.unknown_keys(entry, _KEYS, "'controllers'")
    file = ""
    if isinstance(entry.get("file"), list):
        # the spawner takes several --param-file (spawner.py, jazzy: the controller loads
        # them in order, a later value replacing an earlier); hil reads one file
        reader.fail("controllers: 'file' names one controllers file, not a list",
                    entry.key_lines.get("file", line),
                    hint="put the files' sections into one file, in the spawner's "
                         "--param-file order (a later section's value replaces an earlier)")
    else:
        file = reader.text(entry, "file", "controllers", "")
    names = _pairs(reader, entry, "joint_names", line)
    variables = _pairs(reader, entry, "vars", line)
    for name, value in variables:
        if not VAR_VALUE.fullmatch(value):
            reader.fail(f"controllers: vars: {name} {value!r} is not a plain name, path or "
                        "number", entry.key_lines.get("vars", line),
                        hint="letters, digits and _ . / : - only")
    active = entry.get("active")
    if active is not None and (not isinstance(active, list) or
                               not all(isinstance(a, str) and a for a in active)):
        reader.fail("controllers: 'active' must be a list of controller names",
                    entry.key_lines.get("active", line))
        active = None
    return ControllersSource(reader.path.parent / file, names, variables,
                             tuple(active) if active is not None else None, line)


def _pairs(reader: Reader, entry: LineMapping, key: str, line: int
           ) -> tuple[tuple[str, str], ...]:
    raw = reader.mapping(entry.get(key, LineMapping()), f"controllers: '{key}'",
                         entry.key_lines.get(key, line))
    pairs = []
    for name, value in raw.items():
        if not isinstance(name, str) or not isinstance(value, str):
            reader.fail(f"controllers: {key}: {name!r}: {value!r} must map a name to a name",
                        raw.key_lines.get(name, raw.line))
            continue
        pairs.append((name, value))
    return tuple(pairs)
