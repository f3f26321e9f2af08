"""What gravity asks of each joint, from the robot's description alone: the master's model
for torque feed-forward (a drive's ``torque_feed_forward: gravity``).

A master knows its robot from its description, never from the plant behind the drives. The
model is MuJoCo's recursive Newton-Euler (``mj_rne`` at rest: the joint forces that hold
the robot against gravity) on a model of the master's own, built here from the description
with MuJoCo's MjSpec: the links' masses and centres of mass on the joints' origins and axes,
nothing else (no geoms, meshes, limits or scene; not the plant's model, which the controller
never loads). The root stands upright on the world (a floating base's tilt is not known to
the master). A joint that mimics another is placed from its leader and puts its load on it
(virtual work: ``tau_leader += multiplier tau``); a movable joint no drive moves is taken at
zero.

MuJoCo in place of a pass over the links written by hand (plain floats, compiled with mypyc):
the G1's 39 links in 8 µs a call against 60 µs (docs/performance.md, "2026-12-07: the
master's gravity by MuJoCo").
"""

from __future__ import annotations

from collections.abc import Sequence

import mujoco
import numpy as np

from hil.description import WORLD, Joint, JointType, RobotDescription
from hil.description.rotations import rpy_quaternion

#: m/s^2: MuJoCo's default, the plant's
GRAVITY = 9.81
#: kg·m²: each body's principal inertia. At rest a body's inertia asks no torque, so the
#: model gives every body this one (MuJoCo wants a positive inertia on a moving body; the
#: description's own may not pass MuJoCo's checks, and it changes nothing here)
_INERTIA = 1e-6


class GravityModel:
    """The joint torques (N·m, N) that hold the robot still against gravity at given
    positions of ``joint_names``: the torques a drive adds as feed-forward."""

    def __init__(self, robot: RobotDescription, joint_names: Sequence[str],
                 gravity: float = GRAVITY):
        self.joint_names = tuple(joint_names)
        spec = mujoco.MjSpec()
        spec.compiler.degree = False
        spec.option.gravity = (0.0, 0.0, -gravity)
        if robot.root_link == WORLD:
            for joint in robot.children_of(WORLD):
                _add_link(spec.worldbody, robot, joint.child, joint)
        else:
            _add_link(spec.worldbody, robot, robot.root_link, None)
        self._model = spec.compile()
        self._data = mujoco.MjData(self._model)
        self._forces = np.zeros(self._model.nv)
        # the pure maps between the drives' joints and the model's (hinges and slides only:
        # a joint's qpos and dof share their index): positions in, loads out
        index = {name: k for k, name in enumerate(self.joint_names)}
        into = np.zeros((self._model.nq, len(self.joint_names)))
        offset = np.zeros(self._model.nq)
        for joint in robot.joints:
            leader = joint.mimic.joint if joint.mimic is not None else joint.name
            if not joint.is_movable or leader not in index:
                continue            # not in the model, or at zero there
            address = self._model.joint(joint.name).qposadr[0]
            into[address, index[leader]] = (joint.mimic.multiplier if joint.mimic is not None
                                            else 1.0)
            offset[address] = joint.mimic.offset if joint.mimic is not None else 0.0
        self._into, self._offset = into, offset
        self._onto = np.ascontiguousarray(into.T)       # virtual work: the transpose

    def torques(self, positions: Sequence[float] | np.ndarray) -> np.ndarray:
        """Per joint of ``joint_names``: the torque (N·m) or force (N) that holds it against
        the weight it carries at ``positions``."""
        model, data = self._model, self._data
        data.qpos[:] = self._into.dot(np.asarray(positions, dtype=float)) + self._offset
        mujoco.mj_kinematics(model, data)
        mujoco.mj_comPos(model, data)
        mujoco.mj_rne(model, data, 0, self._forces)
        return self._onto.dot(self._forces)


def _add_link(parent, robot: RobotDescription, name: str, joint: Joint | None) -> None:
    """The link's body on ``parent`` (through ``joint``), its movable joint, its mass at its
    centre, and the links below it."""
    body = parent.add_body(name=name)
    if joint is not None:
        body.pos = joint.origin.xyz
        x, y, z, w = rpy_quaternion(joint.origin.rpy)
        body.quat = (w, x, y, z)                     # MuJoCo's order
        if joint.is_movable:
            mj_joint = body.add_joint(name=joint.name)
            mj_joint.type = (mujoco.mjtJoint.mjJNT_SLIDE if joint.type is JointType.PRISMATIC
                             else mujoco.mjtJoint.mjJNT_HINGE)
            mj_joint.axis = joint.axis
    inertial = robot.link(name).inertial
    body.explicitinertial = True
    # a moving link that carries no mass has the 1 g MuJoCo needs from the description
    # (hil.description warns of it), the plant's as well
    body.mass = max(inertial.mass, 0.0) if inertial is not None else 0.0
    body.ipos = inertial.origin.xyz if inertial is not None else (0.0, 0.0, 0.0)
    body.inertia = (_INERTIA, _INERTIA, _INERTIA)
    for child in robot.children_of(name):
        _add_link(body, robot, child.child, child)

