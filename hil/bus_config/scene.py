"""The bus config's ``scene:``: the things in the robot's world, each checked with its line.

Example (a floor under the robot and a 40 mm box of 50 g on a table)::

    scene:
      - {name: floor, shape: plane, xyz: [0, 0, -0.05]}
      - {name: table, shape: box, size: [0.3, 0.3, 0.02], xyz: [0.4, 0, 0.1]}
      - {name: cube, shape: box, size: [0.04, 0.04, 0.04], xyz: [0.4, 0, 0.13], mass: 0.05}
"""

from __future__ import annotations

import math

from hil.bus_config.types import SceneObject
from hil.bus_config.yaml_reader import LineMapping, Reader
from hil.description import Geometry, GeometryKind, Pose, RobotDescription
from hil.description.reader import MAX_MESH_BYTES
from hil.input_files import file_problem

#: the most objects a scene may hold (hil's choice: a bench's world is a floor, tables and
#: a few things to pick). Moving objects that start inside each other make contacts that
#: grow with the square of their count: 2000 overlapping cubes took 6 GB and 23 s to build
#: the plant, 100 overran MuJoCo's arena (FatalError), 80 took 130 MB (measured 2026-12-06)
MAX_OBJECTS = 64
#: the largest size (m, or a mesh's scale) and distance from the origin (m) a scene object
#: may have (hil's choice: a bench's world; a box of 1e300 m has an infinite inertia)
MAX_EXTENT = 100.0
#: the name of MuJoCo's world body, which no scene object takes either (read_scene)
WORLD = "world"
_KEYS = {"name", "shape", "size", "mesh", "xyz", "rpy", "mass", "friction"}
#: how many numbers ``size`` takes per shape, and what they are
_SIZES = {GeometryKind.BOX: (3, "[x, y, z] edge lengths (m)"),
          GeometryKind.CYLINDER: (2, "[radius, length] (m)"),
          GeometryKind.SPHERE: (1, "[radius] (m)"),
          GeometryKind.MESH: (3, "[x, y, z] scale"),
          GeometryKind.PLANE: (0, "nothing: a plane is endless")}


def read_scene(reader: Reader, top: LineMapping,
               robot: RobotDescription) -> tuple[SceneObject, ...]:
    """The ``scene:`` list (none: the robot alone); names the ``robot``'s links and joints
    take are refused (hil's choice, so that a name in hil's messages and ``hil check``'s list
    is one thing's; in the plant's MuJoCo model the scene's objects are apart anyway:
    hil.plant.shapes.SCENE_NAMESPACE)."""
    if "scene" not in top:
        return ()
    raw = top["scene"]
    line = top.key_lines.get("scene", top.line)
    if not isinstance(raw, list):
        reader.fail("'scene' must be a list of objects ({name: ..., shape: ..., ...})", line)
        return ()
    if len(raw) > MAX_OBJECTS:
        reader.fail(f"'scene' holds {len(raw)} objects, over the {MAX_OBJECTS} hil builds",
                    line, hint="a scene is the few things the robot touches: a floor, tables, "
                               "what it picks")
        return ()
    objects = tuple(o for o in (_read_object(reader, item, number + 1, line)
                                for number, item in enumerate(raw)) if o is not None)
    taken = {WORLD} | {part.name for part in (*robot.links, *robot.joints)}
    seen: set[str] = set()
    for thing in objects:
        if thing.name in seen:
            reader.fail(f"scene: two objects are named '{thing.name}'", thing.line,
                        hint="give every scene object its own name")
        elif thing.name in taken:
            reader.fail(f"scene object '{thing.name}': the robot's model has a link, joint or "
                        "body of that name", thing.line, hint="give the object another name")
        seen.add(thing.name)
    return objects


def _read_object(reader: Reader, raw, number: int, list_line: int | None) -> SceneObject | None:
    item = reader.mapping(raw, f"scene object {number}", list_line)
    if not item:
        return None
    reader.unknown_keys(item, _KEYS, f"scene object {number}")
    name = reader.text(item, "name", f"scene object {number}", f"object{number}")
    what = f"scene object '{name}'"
    shape_text = item.get("shape", "")
    try:
        kind = GeometryKind(shape_text)
    except ValueError:
        reader.fail(f"{what}: unknown shape {shape_text!r}", item.key_lines.get("shape", item.line),
                    hint=f"use one of {', '.join(k.value for k in GeometryKind)}")
        return None
    size = _read_size(reader, item, kind, what)
    mesh = None
    if kind is GeometryKind.MESH:
        mesh = reader.path.parent / reader.text(item, "mesh", what, "")
        problem = file_problem(mesh, MAX_MESH_BYTES)     # MuJoCo reads the file by its name
        if problem:
            reader.fail(f"{what}: mesh file '{mesh}' {problem}",
                        item.key_lines.get("mesh", item.line),
                        hint="'mesh' is an STL or OBJ path relative to the config file")
    elif "mesh" in item:
        reader.fail(f"{what}: 'mesh' is for shape: mesh, not {kind.value}",
                    item.key_lines.get("mesh", item.line))
    mass = float(reader.number(item, "mass", what, 0.0, positive=False))
    if mass < 0:
        reader.fail(f"{what}: 'mass' must be >= 0 (0: fixed in the world), not {mass:g}",
                    item.key_lines.get("mass", item.line))
    if kind is GeometryKind.PLANE and mass > 0:
        reader.fail(f"{what}: a plane cannot move: leave out its 'mass'",
                    item.key_lines.get("mass", item.line))
    friction = float(reader.number(item, "friction", what, 1.0))
    pose = Pose(_read_vector(reader, item, "xyz", what), _read_vector(reader, item, "rpy", what))
    return SceneObject(name, Geometry(kind, size, mesh=mesh), pose, max(mass, 0.0), friction,
                       item.line)


def _read_size(reader: Reader, item: LineMapping, kind: GeometryKind,
               what: str) -> tuple[float, ...]:
    count, meaning = _SIZES[kind]
    line = item.key_lines.get("size", item.line)
    if count == 0:
        if "size" in item:
            reader.fail(f"{what}: a {kind.value} takes no 'size'", line)
        return ()
    if kind is GeometryKind.MESH and "size" not in item:
        return (1.0, 1.0, 1.0)
    value = item.get("size")
    if (not isinstance(value, list) or len(value) != count
            or not all(_positive_number(v) for v in value)):
        reader.fail(f"{what}: 'size' of a {kind.value} is {meaning}, each > 0 and at most "
                    f"{MAX_EXTENT:g}, not {value!r}", line)
        return (0.01,) * count
    return tuple(float(v) for v in value)


def _read_vector(reader: Reader, item: LineMapping, key: str,
                 what: str) -> tuple[float, float, float]:
    value = item.get(key, [0.0, 0.0, 0.0])
    if (not isinstance(value, list) or len(value) != 3
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                       and math.isfinite(v) and (key != "xyz" or abs(v) <= MAX_EXTENT)
                       for v in value)):
        unit = f"m, each within ±{MAX_EXTENT:g}" if key == "xyz" else "rad, roll pitch yaw"
        reader.fail(f"{what}: '{key}' must be three numbers ({unit}), not {value!r}",
                    item.key_lines.get(key, item.line))
        return (0.0, 0.0, 0.0)
    return tuple(float(v) for v in value)


def _positive_number(value) -> bool:
    return (isinstance(value, (int, float)) and not isinstance(value, bool)
            and math.isfinite(value) and 0 < value <= MAX_EXTENT)

