"""Corrections that let descriptions published for ROS tools and Gazebo simulate in MuJoCo.

Many public URDFs carry inertias MuJoCo's compiler rejects (principal moments that break
the triangle inequality, tensors that are not positive definite) and links that move but
have no mass. ROS tools and Gazebo accept them; MuJoCo offers ``balanceinertia`` for the
first. hil corrects them before MuJoCo sees them, so that each correction is a warning
that names the link and what changed (``--strict`` makes them errors).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from hil.description.model import WORLD, Inertial, Joint, Link, Pose
from hil.description.reader import ElementReader
from hil.errors import warning

#: mass and inertia given to a link that moves but carries no mass (MuJoCo needs some)
PLACEHOLDER_MASS = 1e-3         # kg
PLACEHOLDER_INERTIA = 1e-7      # kg m^2, each principal moment
#: changes smaller than this (relative to the largest moment) are rounding in the file's
#: digits: corrected, not reported
REPORTED_CHANGE = 1e-4


def physical_inertia(inertial: Inertial) -> tuple[Inertial, str | None]:
    """The inertial with a tensor MuJoCo accepts, and what changed (None: nothing to say).

    Principal moments below a millionth of the largest are raised to it (a tensor must be
    positive definite); moments that break A + B >= C are all set to their mean, as
    MuJoCo's ``balanceinertia`` does. The principal axes are kept.
    """
    if inertial.mass <= 0:
        return inertial, None
    tensor = np.array([[inertial.ixx, inertial.ixy, inertial.ixz],
                       [inertial.ixy, inertial.iyy, inertial.iyz],
                       [inertial.ixz, inertial.iyz, inertial.izz]])
    moments, axes = np.linalg.eigh(tensor)
    fixed = np.maximum(moments, max(float(moments.max()) * 1e-6, 1e-12))
    if any(fixed[a] + fixed[b] < fixed[c] for a, b, c in ((0, 1, 2), (1, 2, 0), (2, 0, 1))):
        fixed[:] = fixed.mean()
    if np.array_equal(fixed, moments):
        return inertial, None
    corrected = axes @ np.diag(fixed) @ axes.T
    result = replace(inertial, ixx=float(corrected[0, 0]), iyy=float(corrected[1, 1]),
                     izz=float(corrected[2, 2]), ixy=float(corrected[0, 1]),
                     ixz=float(corrected[0, 2]), iyz=float(corrected[1, 2]))
    change = float(np.abs(fixed - moments).max()) / max(float(np.abs(moments).max()), 1e-12)
    if change < REPORTED_CHANGE:
        return result, None
    return result, (f"principal moments ({', '.join(f'{m:.4g}' for m in moments)}) "
                    f"-> ({', '.join(f'{m:.4g}' for m in fixed)}) kg m^2")


def _rigid_mass(links: tuple[Link, ...], joints: tuple[Joint, ...]) -> Callable[[str], float]:
    """The mass (kg) of a link with the links fixed to it, down the tree: MuJoCo's body
    and the bodies welded to it, which move as one."""
    mass = {link.name: link.inertial.mass if link.inertial else 0.0 for link in links}
    fixed_children: dict[str, list[str]] = {}
    for joint in joints:
        if not joint.is_movable:
            fixed_children.setdefault(joint.parent, []).append(joint.child)

    def rigid_mass(link: str, seen: set[str]) -> float:
        if link in seen:             # a loop is reported by the tree check
            return 0.0
        seen.add(link)
        return mass.get(link, 0.0) + sum(rigid_mass(child, seen)
                                         for child in fixed_children.get(link, ()))

    return lambda link: rigid_mass(link, set())


def massless_moving_links(links: tuple[Link, ...], joints: tuple[Joint, ...]) -> list[str]:
    """Links that a movable joint moves and that carry no mass, counting the links fixed to
    them (MuJoCo rejects a moving body whose rigid part has none)."""
    names = {link.name for link in links}
    rigid_mass = _rigid_mass(links, joints)
    return [j.child for j in joints if j.is_movable and j.child in names
            and rigid_mass(j.child) <= 0.0]


def massless_free_links(links: tuple[Link, ...], joints: tuple[Joint, ...]) -> list[str]:
    """The links a floating base frees (the root; under a root named WORLD, each link fixed
    to it) that carry no mass, counting the links fixed to them. MuJoCo's compiler refuses
    to move a body without mass ("mass and inertia of moving bodies must be larger than
    mjMINVAL") and keeps a welded one without; URDF's tools take a root link without
    ``<inertial>`` as fixed to the world (kdl_parser's treeFromUrdfModel warns of a root
    link *with* one: KDL's root does not move)."""
    children = {j.child for j in joints}
    roots = [link.name for link in links if link.name not in children]
    if len(roots) != 1:              # no tree: reported by the tree check
        return []
    tops = ([j.child for j in joints if j.parent == WORLD and not j.is_movable]
            if roots[0] == WORLD else roots)
    rigid_mass = _rigid_mass(links, joints)
    return [link for link in tops if rigid_mass(link) <= 0.0]


def placeholder_inertial(link: Link) -> Inertial:
    """A small mass at the link's origin (or its inertial's): PLACEHOLDER_MASS, INERTIA."""
    origin = link.inertial.origin if link.inertial else Pose()
    return Inertial(mass=PLACEHOLDER_MASS, origin=origin, ixx=PLACEHOLDER_INERTIA, ixy=0.0,
                    ixz=0.0, iyy=PLACEHOLDER_INERTIA, iyz=0.0, izz=PLACEHOLDER_INERTIA)


def give_moving_links_mass(reader: ElementReader, links: tuple[Link, ...],
                           joints: tuple[Joint, ...]) -> tuple[Link, ...]:
    """The links, each massless moving one given PLACEHOLDER_MASS, with a warning."""
    massless = set(massless_moving_links(links, joints))
    for name in sorted(massless):
        reader.report(warning, f"link '{name}' moves but has no mass (nor any link fixed to "
                      f"it); MuJoCo needs some: given {PLACEHOLDER_MASS * 1e3:g} g and "
                      f"{PLACEHOLDER_INERTIA:g} kg m^2", "link", name,
                      hint="give the link an <inertial> with its real mass")
    return tuple(replace(link, inertial=placeholder_inertial(link)) if link.name in massless
                 else link for link in links)


def note_ignored_axes(reader: ElementReader) -> None:
    """One warning naming every fixed/floating joint whose zero axis was ignored."""
    names = reader.ignored_axes
    if names:
        reader.report(warning, f"{len(names)} fixed/floating joint(s) have <axis xyz=\"0 0 0\">,"
                      f" ignored as URDF ignores their axis: {', '.join(names)}", "joint",
                      names[0], hint="remove the <axis> from joints that do not move")


def note_world_link(reader: ElementReader, links: tuple[Link, ...],
                    joints: tuple[Joint, ...]) -> None:
    """Say that a root link named WORLD is taken as the fixed world."""
    children = {j.child for j in joints}
    roots = [link for link in links if link.name not in children]
    if len(roots) == 1 and roots[0].name == WORLD:
        reader.report(warning, f"the root link is '{WORLD}': hil fixes its children to "
                      "MuJoCo's world body (the robot's base is fixed)", "link", WORLD,
                      hint="nothing to do, unless the link was not meant as the world")
