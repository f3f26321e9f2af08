"""What gravity asks of each joint, from the robot's description alone: the master's model
for torque feed-forward (a drive's ``torque_feed_forward: gravity``).

A master knows its robot from its description, never from the plant behind the drives, so
the model is built here from the links' masses and centres of mass and the joints' origins
and axes: a forward pass places every link at the given joint positions, a backward pass
sums the weight each joint carries and the moment of that weight about its axis. The root
stands upright (a floating base's tilt is not known to the master). A joint that mimics
another puts its load on its leader (virtual work: ``tau_leader += multiplier tau``); a
movable joint no drive moves is taken at zero.

Written in plain floats: numpy on a few 3-vectors per joint cost as much as a 1 kHz cycle's
whole budget (docs/performance.md, "2026-12-06, later: figures from code comments"). The
install compiles it with mypyc (``hil.compiled.COMPILED_MASTER``): keep it typed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from hil.description import JointType, RobotDescription
from hil.description.rotations import rpy_matrix

Vec = tuple[float, float, float]
Mat = tuple[float, float, float, float, float, float, float, float, float]   # row-major

#: m/s^2: MuJoCo's default, the plant's
GRAVITY = 9.81
_IDENTITY: Mat = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)


class GravityModel:
    """The joint torques (N·m, N) that hold the robot still against gravity at given
    positions of ``joint_names``: the torques a drive adds as feed-forward."""

    def __init__(self, robot: RobotDescription, joint_names: Sequence[str],
                 gravity: float = GRAVITY):
        self.joint_names = tuple(joint_names)
        self._gravity = gravity
        index = {name: k for k, name in enumerate(self.joint_names)}
        order = _links_from_root(robot)
        slot = {link: k for k, link in enumerate(order)}
        into = {j.child: j for j in robot.joints}
        self._parent: list[int] = []
        self._turn: list[Mat] = []          # the joint origin's rotation, in the parent
        self._shift: list[Vec] = []         # the joint origin's translation, in the parent
        self._axis: list[Vec] = []          # in the joint's own frame
        self._kind: list[int] = []          # 0 fixed (or undriven), 1 rotary, 2 prismatic
        self._source: list[int] = []        # position index of the joint (or its leader)
        self._scale: list[float] = []       # mimic multiplier (1 for its own)
        self._bias: list[float] = []        # mimic offset
        self._mass: list[float] = []
        self._com: list[Vec] = []           # in the link's frame
        for link in order:
            joint = into.get(link)
            inertial = robot.link(link).inertial
            self._mass.append(inertial.mass if inertial is not None else 0.0)
            self._com.append(_vec(inertial.origin.xyz) if inertial is not None
                             else (0.0, 0.0, 0.0))
            if joint is None:
                self._parent.append(-1)
                self._turn.append(_IDENTITY)
                self._shift.append((0.0, 0.0, 0.0))
                self._axis.append((0.0, 0.0, 1.0))
                self._kind.append(0)
                self._source.append(-1)
                self._scale.append(1.0)
                self._bias.append(0.0)
                continue
            self._parent.append(slot[joint.parent])
            self._turn.append(rpy_matrix(joint.origin.rpy))
            self._shift.append(_vec(joint.origin.xyz))
            self._axis.append(_unit(joint.axis))
            leader = joint.mimic.joint if joint.mimic is not None else joint.name
            moves = joint.is_movable and leader in index
            self._kind.append(0 if not moves else 2 if joint.type is JointType.PRISMATIC
                              else 1)
            self._source.append(index[leader] if moves else -1)
            self._scale.append(joint.mimic.multiplier if joint.mimic is not None else 1.0)
            self._bias.append(joint.mimic.offset if joint.mimic is not None else 0.0)

    def torques(self, positions: Sequence[float]) -> list[float]:
        """Per joint of ``joint_names``: the torque (N·m) or force (N) that holds it against
        the weight it carries at ``positions``."""
        count = len(self._parent)
        turns: list[Mat] = []
        places: list[Vec] = []
        axes: list[Vec] = []
        for k in range(count):
            parent = self._parent[k]
            if parent < 0:
                turns.append(_IDENTITY)
                places.append((0.0, 0.0, 0.0))
                axes.append((0.0, 0.0, 1.0))
                continue
            base = _compose(turns[parent], self._turn[k])
            place = _add(places[parent], _apply(turns[parent], self._shift[k]))
            axis = _apply(base, self._axis[k])
            kind = self._kind[k]
            if kind != 0:
                q = self._scale[k] * positions[self._source[k]] + self._bias[k]
                if kind == 1:
                    base = _compose(base, _about(self._axis[k], q))
                else:
                    place = _add(place, _scaled(axis, q))
            turns.append(base)
            places.append(place)
            axes.append(axis)
        carried = [0.0] * count                        # the weight below each link (kg)
        moment: list[Vec] = [(0.0, 0.0, 0.0)] * count  # sum of mass x centre (kg m)
        for k in range(count - 1, -1, -1):
            mass = self._mass[k]
            centre = _add(places[k], _apply(turns[k], self._com[k]))
            carried[k] += mass
            moment[k] = _add(moment[k], _scaled(centre, mass))
            parent = self._parent[k]
            if parent >= 0:
                carried[parent] += carried[k]
                moment[parent] = _add(moment[parent], moment[k])
        loads = [0.0] * len(self.joint_names)
        g = self._gravity
        for k in range(count):
            kind = self._kind[k]
            if kind == 0:
                continue
            axis = axes[k]
            if kind == 1:
                # the weight's moment about the axis through the joint: (M c - M p) x (0,0,-g)
                arm = _add(moment[k], _scaled(places[k], -carried[k]))
                hold = g * (axis[0] * arm[1] - axis[1] * arm[0])
            else:
                hold = g * carried[k] * axis[2]
            loads[self._source[k]] += self._scale[k] * hold
        return loads


def _links_from_root(robot: RobotDescription) -> list[str]:
    """Every link, each after its parent."""
    children: dict[str, list[str]] = {}
    for joint in robot.joints:
        children.setdefault(joint.parent, []).append(joint.child)
    order = [robot.root_link]
    for link in order:
        order.extend(children.get(link, []))
    return order


def _vec(v) -> Vec:
    return (float(v[0]), float(v[1]), float(v[2]))


def _unit(v) -> Vec:
    norm = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]) or 1.0
    return (v[0] / norm, v[1] / norm, v[2] / norm)


def _about(axis: Vec, angle: float) -> Mat:
    """Rodrigues: the rotation by ``angle`` about the unit ``axis``."""
    x, y, z = axis
    c, s = math.cos(angle), math.sin(angle)
    t = 1.0 - c
    return (t * x * x + c, t * x * y - s * z, t * x * z + s * y,
            t * x * y + s * z, t * y * y + c, t * y * z - s * x,
            t * x * z - s * y, t * y * z + s * x, t * z * z + c)


def _compose(a: Mat, b: Mat) -> Mat:
    return (a[0] * b[0] + a[1] * b[3] + a[2] * b[6], a[0] * b[1] + a[1] * b[4] + a[2] * b[7],
            a[0] * b[2] + a[1] * b[5] + a[2] * b[8],
            a[3] * b[0] + a[4] * b[3] + a[5] * b[6], a[3] * b[1] + a[4] * b[4] + a[5] * b[7],
            a[3] * b[2] + a[4] * b[5] + a[5] * b[8],
            a[6] * b[0] + a[7] * b[3] + a[8] * b[6], a[6] * b[1] + a[7] * b[4] + a[8] * b[7],
            a[6] * b[2] + a[7] * b[5] + a[8] * b[8])


def _apply(m: Mat, v: Vec) -> Vec:
    return (m[0] * v[0] + m[1] * v[1] + m[2] * v[2], m[3] * v[0] + m[4] * v[1] + m[5] * v[2],
            m[6] * v[0] + m[7] * v[1] + m[8] * v[2])


def _add(a: Vec, b: Vec) -> Vec:
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


def _scaled(v: Vec, s: float) -> Vec:
    return (v[0] * s, v[1] * s, v[2] * s)
