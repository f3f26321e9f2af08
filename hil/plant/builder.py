"""Robot description -> MuJoCo model, through ``mujoco.MjSpec``.

The body tree is built directly from the typed description rather than by
MuJoCo's URDF importer, because that importer ignores transmissions, drops
visuals and fails on missing meshes; building from the description keeps one
parser (hil's, with its error messages) and lets transmissions act in physics:

* a SimpleTransmission becomes a motor actuator on the joint with
  ``gear = reduction``, so actuator length = motor position (for a zero
  offset) and actuator force = motor torque; the rotor's reflected inertia
  ``J N^2`` is the joint's armature;
* a Differential/FourBar transmission becomes one fixed tendon per actuator
  whose coefficients are the row of the position map ``a = P q``; a motor on
  that tendon applies ``P^T tau_a`` to the joints (virtual work) and the
  tendon's armature ``J`` adds exactly the reflected inertia ``P^T J P``;
* joint damping and Coulomb friction come from ``<dynamics>``; mimic joints
  are joint equality constraints ``q = multiplier q_leader + offset``;
* motor torque range is the joint effort limit mapped through the
  transmission (effort / reduction for a simple one).

Links' shapes and the scene they touch: :mod:`hil.plant.shapes`.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Protocol

import mujoco
import numpy as np

from hil.description import (
    WORLD, Joint, JointType, Link, RobotDescription,
)
from hil.description.reader import SourceIndex
from hil.errors import ConfigError
from hil.plant.shapes import ScenePart, add_collisions, add_scene, add_visuals, rpy_to_quat
from hil.transmissions import SimpleTransmission, Transmission

DEFAULT_TIMESTEP = 0.001
#: the free joint of a floating base (the bus config's ``base: floating``)
FLOATING_BASE = "floating_base"
#: the gear's own hinge beside a joint's (backlash, gear compliance): its name
GEAR_STAGE = "{joint}_gear"
@dataclass(frozen=True)
class ActuatorBinding:
    """Where one actuator of a transmission lives in the MuJoCo model."""

    name: str
    transmission: int
    index_in_transmission: int
    torque_limit: float


#: MuJoCo solimp of a motor's Coulomb friction (dmin, dmax, width, midpoint, power)
STICTION_IMPEDANCE = (0.99, 0.999, 0.001, 0.5, 2.0)


class ActuatorLosses(Protocol):
    """What the plant models of a real motor and gear (a bus config's ``ActuatorEffects`` is
    one): each 0 for none. Motor side but for the gear's own, at its output."""

    coulomb_friction: float      # N·m
    viscous_friction: float      # N·m·s/rad
    delay: float                 # s
    backlash: float              # rad (m), output side
    gear_stiffness: float        # N·m/rad (N/m), output side
    gear_damping: float          # N·m·s/rad (N·s/m), output side


def build_spec(description: RobotDescription, transmissions: tuple[Transmission, ...],
               timestep: float = DEFAULT_TIMESTEP,
               losses: Mapping[str, ActuatorLosses] | None = None,
               scene: tuple[ScenePart, ...] = (), floating_base: bool = False,
               ) -> tuple[mujoco.MjSpec, tuple[ActuatorBinding, ...]]:
    """The robot's model; with ``floating_base`` its root body (or, under a ``world`` link,
    each body on it) moves freely on a free joint named FLOATING_BASE instead of being
    welded to the world."""
    spec = mujoco.MjSpec()
    spec.modelname = description.name
    spec.compiler.degree = False
    # a link's inertia is its URDF's (explicit) and its geoms are massless; a scene object's
    # comes from its geom
    spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_AUTO
    spec.option.timestep = timestep
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST

    armature = _reflected_joint_armature(description, transmissions)
    if description.root_link == WORLD:        # MuJoCo's world body is that link
        tops = [_add_body(spec, spec.worldbody, description, child.child, child, armature)
                for child in description.children_of(WORLD)]
    else:
        tops = [_add_body(spec, spec.worldbody, description, description.root_link, None,
                          armature)]
    if floating_base:
        for number, top in enumerate(tops):
            if top.first_joint() is not None:          # a movable joint to the world: kept
                continue
            top.add_freejoint(name=FLOATING_BASE if number == 0
                              else f"{FLOATING_BASE}_{number}")
    add_scene(spec, scene)
    _add_mimic_constraints(spec, description)
    bindings = _add_actuators(spec, description, transmissions)
    for binding in bindings:
        if losses and binding.name in losses:
            _add_losses(spec, transmissions[binding.transmission], binding, losses[binding.name],
                        timestep)
    return spec, bindings


def _add_losses(spec: mujoco.MjSpec, transmission: Transmission, binding: ActuatorBinding,
                losses: ActuatorLosses, timestep: float) -> None:
    """MuJoCo's own models of a motor's losses, at the motor: Coulomb friction as the
    frictionloss of what the motor turns (its joint, seen through the reduction, or its
    tendon), viscous friction as the actuator's damping, the delay as the actuator's (a
    history of its controls, zero-order hold)."""
    actuator = spec.actuator(binding.name)
    if losses.coulomb_friction:
        if isinstance(transmission, SimpleTransmission):
            turned = spec.joint(transmission.joints[0])
            turned.frictionloss += losses.coulomb_friction * abs(transmission.reduction)
        else:
            turned = spec.tendon(f"{binding.name}_tendon")
            turned.frictionloss = losses.coulomb_friction
        # MuJoCo's friction is a soft constraint: at its defaults a motor held at 3/4 of its
        # breakaway torque crept at 1.7 % of the speed a torque as far above it gives (one
        # axis, 1 ms steps); at the stiffest time constant the step allows (2 steps) and a
        # hard impedance, at 0.02 %
        turned.solref_friction = [2 * timestep, 1.0]
        turned.solimp_friction = list(STICTION_IMPEDANCE)
    if losses.viscous_friction:
        actuator.damping = [losses.viscous_friction, 0.0, 0.0]
    steps = round(losses.delay / timestep)      # the bus config says so where it rounds
    if steps:
        actuator.delay = steps * timestep
        actuator.nsample = steps + 1
        actuator.interp = 0
    if losses.backlash or losses.gear_stiffness:
        _add_gear_stage(spec, transmission.joints[0], losses, timestep)


def _add_gear_stage(spec: mujoco.MjSpec, joint_name: str, losses: ActuatorLosses,
                    timestep: float) -> None:
    """The gear between the motor and the link as a second hinge (or slide) on the joint's
    axis, in the same body (MuJoCo's way to model backlash: it has no backlash or gear
    compliance of its own). The motor turns the joint's own; the link sits at the sum of
    the two; the second, GEAR_STAGE, turns freely within ±backlash/2 (ends as stiff as the
    step allows), or against the gear's stiffness and damping."""
    joint = spec.joint(joint_name)
    stage = joint.parent.add_joint(name=GEAR_STAGE.format(joint=joint_name), type=joint.type,
                                   axis=joint.axis, pos=joint.pos)
    if losses.backlash:
        stage.limited = mujoco.mjtLimited.mjLIMITED_TRUE
        stage.range = (-losses.backlash / 2, losses.backlash / 2)
        stage.solref_limit = [2 * timestep, 1.0]
        stage.solimp_limit = list(STICTION_IMPEDANCE)
    else:
        stage.limited = mujoco.mjtLimited.mjLIMITED_FALSE
        stage.stiffness = [losses.gear_stiffness, 0.0, 0.0]
        stage.damping = [losses.gear_damping, 0.0, 0.0]


def compile_model(spec: mujoco.MjSpec, description: RobotDescription) -> mujoco.MjModel:
    try:
        return spec.compile()
    except ValueError as exc:
        text = " ".join(str(exc).split())
        element = re.search(r"Element name '([^']*)'", text)
        name = element.group(1) if element else ""
        kind = ("link" if name in {link.name for link in description.links} else
                "joint" if name in {joint.name for joint in description.joints} else None)
        file, line = (SourceIndex(description.files).locate(kind, name) if kind
                      else (description.source, None))
        raise ConfigError.single(f"MuJoCo rejects the model of '{description.name}': {text}",
                                 file, line,
                                 hint=f"check {kind} '{name}' (its inertial and limits)" if kind
                                 else "check the links' inertials and the joints' limits") from None


def _reflected_joint_armature(description: RobotDescription,
                              transmissions: tuple[Transmission, ...]) -> dict[str, float]:
    return {t.joints[0]: spec.actuators[0].rotor_inertia * t.reduction ** 2
            for spec, t in zip(description.transmissions, transmissions)
            if isinstance(t, SimpleTransmission)}


def _add_body(spec: mujoco.MjSpec, parent, description: RobotDescription, link_name: str,
              joint: Joint | None, armature: dict[str, float]):
    """The link's body, its joint, geoms and the bodies below it; returns the body."""
    link = description.link(link_name)
    body = parent.add_body(name=link.name)
    if joint is not None:
        body.pos = joint.origin.xyz
        body.quat = rpy_to_quat(joint.origin.rpy)
        if joint.is_movable:
            _add_joint(body, joint, armature.get(joint.name, 0.0))
    _set_inertial(body, link)
    add_visuals(spec, body, link)
    add_collisions(spec, body, link)
    for child in description.children_of(link.name):
        _add_body(spec, body, description, child.child, child, armature)
    return body


def _add_joint(body, joint: Joint, armature: float) -> None:
    mj_joint = body.add_joint(name=joint.name)
    mj_joint.type = (mujoco.mjtJoint.mjJNT_SLIDE if joint.type is JointType.PRISMATIC
                     else mujoco.mjtJoint.mjJNT_HINGE)
    mj_joint.axis = joint.axis
    limits = joint.limits
    if limits is not None and limits.lower is not None:
        mj_joint.limited = mujoco.mjtLimited.mjLIMITED_TRUE
        mj_joint.range = (limits.lower, limits.upper)
    else:
        mj_joint.limited = mujoco.mjtLimited.mjLIMITED_FALSE
    # MuJoCo 4 takes [linear, polynomial terms...]; URDF damping is the linear one.
    mj_joint.damping = [joint.dynamics.damping, 0.0, 0.0]
    mj_joint.frictionloss = joint.dynamics.friction
    mj_joint.armature = armature


def _set_inertial(body, link: Link) -> None:
    inertial = link.inertial
    if inertial is None or inertial.mass <= 0:
        return
    body.explicitinertial = True
    body.mass = inertial.mass
    body.ipos = inertial.origin.xyz
    body.iquat = rpy_to_quat(inertial.origin.rpy)
    body.fullinertia = (inertial.ixx, inertial.iyy, inertial.izz,
                        inertial.ixy, inertial.ixz, inertial.iyz)


def _add_mimic_constraints(spec: mujoco.MjSpec, description: RobotDescription) -> None:
    for joint in description.joints:
        if joint.mimic is None:
            continue
        equality = spec.add_equality(name=f"mimic_{joint.name}")
        equality.type = mujoco.mjtEq.mjEQ_JOINT
        equality.objtype = mujoco.mjtObj.mjOBJ_JOINT
        equality.name1, equality.name2 = joint.name, joint.mimic.joint
        # Stiffer than MuJoCo's default (0.02 s) so the follower lags by well under
        # a millimetre; two timesteps is the stiffest MuJoCo integrates stably.
        equality.solref = (2 * spec.option.timestep, 1.0)
        polynomial = np.zeros_like(equality.data)  # q = c0 + c1 q_leader + c2 q_leader^2 ...
        polynomial[:2] = (joint.mimic.offset, joint.mimic.multiplier)
        equality.data = polynomial


def _add_actuators(spec: mujoco.MjSpec, description: RobotDescription,
                   transmissions: tuple[Transmission, ...]) -> tuple[ActuatorBinding, ...]:
    bindings = []
    for t_index, (t_spec, transmission) in enumerate(zip(description.transmissions,
                                                          transmissions)):
        efforts = [description.joint(j).limits.effort if description.joint(j).limits
                   else math.inf for j in transmission.joints]
        limits = transmission.actuator_effort_limits(efforts)
        for k, name in enumerate(transmission.actuators):
            actuator = spec.add_actuator(name=name)
            if isinstance(transmission, SimpleTransmission):
                actuator.trntype = mujoco.mjtTrn.mjTRN_JOINT
                actuator.target = transmission.joints[0]
                actuator.gear = [transmission.reduction, 0, 0, 0, 0, 0]
            else:
                tendon = spec.add_tendon(name=f"{name}_tendon")
                for j, joint in enumerate(transmission.joints):
                    if transmission.position_matrix[k, j] != 0.0:
                        tendon.wrap_joint(joint, transmission.position_matrix[k, j])
                tendon.armature = t_spec.actuators[k].rotor_inertia
                actuator.trntype = mujoco.mjtTrn.mjTRN_TENDON
                actuator.target = tendon.name
                actuator.gear = [1, 0, 0, 0, 0, 0]
            actuator.gaintype = mujoco.mjtGain.mjGAIN_FIXED
            actuator.gainprm = [1.0] + [0.0] * 9
            actuator.biastype = mujoco.mjtBias.mjBIAS_NONE
            if math.isfinite(limits[k]):
                actuator.ctrllimited = mujoco.mjtLimited.mjLIMITED_TRUE
                actuator.ctrlrange = (-limits[k], limits[k])
            bindings.append(ActuatorBinding(name, t_index, k, float(limits[k])))
    return tuple(bindings)

