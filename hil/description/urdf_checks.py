"""Checks of a URDF robot as a whole, after its links and joints are read: the kinematic
tree, the mimic joints MuJoCo can build, visuals far outside the robot. Each problem is
reported on the reader with the element's file and line."""

from __future__ import annotations

from collections import Counter, defaultdict
from dataclasses import replace
from pathlib import Path

from hil.description.model import Joint, Link
from hil.description.packages import PackagePath, own_package
from hil.description.reader import ElementReader, start_tag
from hil.errors import HilError, error, warning
from hil.input_files import read_input_file


def check_tree(reader: ElementReader, links: tuple[Link, ...], joints: tuple[Joint, ...]) -> None:
    """Unique joint names, defined parent and child links, one tree with one root."""
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
                              hint=_missing_link_hint(reader, link, role))
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
    elif roots and _depth(roots[0], joints) > MAX_DEPTH:
        reader.diagnostics.append(error(
            f"the tree is more than {MAX_DEPTH} joints deep, hil's limit",
            reader.source.path, hint="a robot's chains are tens of joints deep: check that "
                                     "the description is the robot's"))


#: joints from the root to the deepest link that hil builds (its plant and kinematics walk
#: the tree recursively; the limit is hil's, far above any robot's)
MAX_DEPTH = 200


def _depth(root: str, joints: tuple[Joint, ...]) -> int:
    """Joints on the longest path down from ``root``, counted up to MAX_DEPTH + 1 (a tree:
    check_tree's other checks)."""
    children: dict[str, list[str]] = defaultdict(list)
    for joint in joints:
        children[joint.parent].append(joint.child)
    deepest, level = 0, [root]
    while level and deepest <= MAX_DEPTH:
        level = [child for link in level for child in children[link]]
        deepest += bool(level)
    return deepest


def _missing_link_hint(reader: ElementReader, link: str, role: str) -> str:
    """What to do about a link no loaded file defines: the file of the description's own
    package that defines it, if one does; for a missing parent, that the file is likely a
    fragment a robot's main file includes (an arm's gripper, a sensor mount). Other packages
    are not searched: names like ``base_link`` are in every robot, and a file of another
    robot that defines one is no answer."""
    pattern = start_tag("link", link)
    loaded = set(reader.source.files)
    for candidate in _package_files(reader.source.path):
        if candidate.suffix not in (".xacro", ".urdf") or candidate.resolve() in loaded:
            continue
        try:        # a folder or a FIFO named *.xacro, an unreadable file: no answer here
            text = read_input_file(candidate, "description", hint="")
        except HilError:
            continue
        if pattern.search(text):
            return (f"'{link}' is defined in {candidate}, which is not included: add "
                    f"<xacro:include filename=\"{_find_form(candidate, reader.package_path)}\"/>")
    if role == "parent":
        return (f"this file attaches to link '{link}' without defining it: it looks like a "
                "fragment that a robot's main file includes; check that main file instead, "
                f"or define <link name=\"{link}\"/> here to check the fragment alone")
    return f"define <link name=\"{link}\"/> or include the file that defines it"


def _package_files(path: Path) -> list[Path]:
    """The files of the ROS package holding ``path`` (below the nearest folder with a
    package.xml), else those beside ``path`` (a file in no package may lie in a home folder)."""
    package = own_package(path)
    return sorted(package.rglob("*")) if package else sorted(path.resolve().parent.iterdir())


def _find_form(file: Path, package_path: PackagePath) -> str:
    """``$(find pkg)/rel`` for a file inside a package on the path, else the plain path."""
    for name, folder in package_path.packages().items():
        if file.resolve().is_relative_to(folder.resolve()):
            return f"$(find {name})/{file.resolve().relative_to(folder.resolve())}"
    return str(file)


def check_mimic(reader: ElementReader, joints: tuple[Joint, ...]) -> tuple[Joint, ...]:
    """Joints with the mimics MuJoCo can build: a mimic of a joint that does not exist or
    cannot move is left out with a warning (reduced models fix or drop the leader and keep
    the mimic); a mimic of a mimic is an error."""
    by_name = {j.name: j for j in joints}
    kept = []
    for joint in joints:
        leader = by_name.get(joint.mimic.joint) if joint.mimic else None
        if joint.mimic is None:
            pass
        elif not joint.is_movable:
            reader.report(warning, f"{joint.type.value} joint '{joint.name}' has a <mimic>, "
                          "which does not move it: left out", "joint", joint.name,
                          hint="remove the <mimic>, or give the joint a movable type")
            joint = replace(joint, mimic=None)
        elif leader is None or not leader.is_movable:
            why = "does not exist" if leader is None else f"is {leader.type.value}"
            reader.report(warning, f"joint '{joint.name}' mimics joint '{joint.mimic.joint}', "
                          f"which {why}: the <mimic> is left out (the joint is passive)",
                          "joint", joint.name,
                          hint=f"mimic one of: {', '.join(j.name for j in joints if j.is_movable)}")
            joint = replace(joint, mimic=None)
        elif leader.name == joint.name or leader.mimic is not None:
            reader.report(error, f"joint '{joint.name}' mimics '{leader.name}', which is itself "
                          "or a mimic joint", "joint", joint.name,
                          hint="mimic an actuated joint directly")
        kept.append(joint)
    return tuple(kept)


def check_visuals(reader: ElementReader, links: tuple[Link, ...],
                  joints: tuple[Joint, ...]) -> None:
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
