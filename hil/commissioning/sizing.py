"""Choosing a motor and a reduction for a joint from its effort and velocity limits.

``hil init`` uses this where a description has no transmission for a joint. The rule,
documented so that a user can check it against the drive they have:

* the catalogue is a range of generic servo motor classes (:data:`MOTOR_CLASSES`: rated
  torque at 3000 rpm for the class' power, peak 3 x rated, the top speed and rotor inertia
  typical of industrial AC servo motors of that power; small BLDC classes below 50 W);
* the reductions are the usual gearhead and harmonic-drive ratios for a revolute joint
  (:data:`ROTARY_REDUCTIONS`) and ball-screw leads for a prismatic one
  (:data:`SCREW_LEADS_MM`, reduction 2 pi / lead in rad per metre);
* a joint gets the smallest motor class (by peak torque) for which some reduction ``N``
  covers both limits, ``peak x N >= effort`` and ``top speed / N >= velocity``, and whose
  rated (continuous) torque holds the joint's gravity load with margin,
  ``rated x N >= HOLDING_MARGIN x load`` (the holding brake is sized like the rated torque;
  the load is the largest along the demo `hil up --demo` runs, from
  :mod:`hil.commissioning.demo_pace`),
  with the smallest such ``N`` (the least reflected inertia);
* where no class covers both, the largest class with the smallest reduction that covers
  the effort, and the note says the speed falls short.

A joint whose description gives no effort or velocity limit (``0``, or no ``<limit>`` on a
continuous joint, as many public descriptions have it) gets the default class
(:func:`default_limits`) for what is missing: velocity :data:`DEFAULT_VELOCITY` (1 rad/s, or
0.1 m/s for a prismatic joint); effort :data:`DEFAULT_EFFORT_MARGIN` x the largest load
gravity can put on it (the weight of everything it carries at the distance of that weight's
centre from its axis; for a prismatic joint the weight), at least
:data:`DEFAULT_EFFORT_FLOOR` (1 N·m, 10 N).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, replace

from hil.description import Joint, JointLimits, JointType


@dataclass(frozen=True)
class MotorClass:
    name: str
    rated_torque: float       # N·m
    peak_torque: float        # N·m
    top_speed: float          # rad/s
    rotor_inertia: float      # kg m^2
    #: the rotor inertia is hil's estimate (:func:`estimated_reflected_inertia`)
    inertia_estimated: bool = False


#: rad/s: the speed a generic class' rated torque is given at (3000 rpm)
_CLASS_SPEED = 3000 * 2 * math.pi / 60


def _servo(watts: float, top_rpm: float, rotor_inertia: float) -> MotorClass:
    rated = watts / _CLASS_SPEED
    return MotorClass(f"{watts:g} W", round(rated, 4), round(3 * rated, 4),
                      round(top_rpm * 2 * math.pi / 60, 1), rotor_inertia)


MOTOR_CLASSES = (
    _servo(10, 10000, 1.0e-7), _servo(25, 8000, 6.0e-7), _servo(50, 6000, 2.5e-6),
    _servo(100, 6000, 5.1e-6), _servo(200, 6000, 1.5e-5), _servo(400, 6000, 2.7e-5),
    _servo(750, 6000, 1.1e-4), _servo(1000, 5000, 2.6e-4), _servo(1500, 5000, 3.8e-4),
    _servo(2000, 5000, 5.2e-4), _servo(3000, 5000, 1.2e-3), _servo(5000, 5000, 2.1e-3),
)
#: rated torque x reduction over the static gravity load a joint must hold
HOLDING_MARGIN = 1.5
ROTARY_REDUCTIONS = (1, 3, 5, 7, 10, 15, 20, 30, 50, 80, 100, 120, 160)
SCREW_LEADS_MM = (40, 25, 20, 16, 10, 5, 4, 2, 1)


#: the default class: velocity by joint type (rad/s, m/s); effort as the module doc says
DEFAULT_VELOCITY = {JointType.PRISMATIC: 0.1, JointType.REVOLUTE: 1.0, JointType.CONTINUOUS: 1.0}
DEFAULT_EFFORT_MARGIN = 2.0
DEFAULT_EFFORT_FLOOR = {JointType.PRISMATIC: 10.0, JointType.REVOLUTE: 1.0,
                        JointType.CONTINUOUS: 1.0}


def needs_default_limits(joint: Joint) -> bool:
    """Whether the description leaves the joint's effort or velocity limit ungiven."""
    return joint.limits is None or joint.limits.effort <= 0 or joint.limits.velocity <= 0


def default_limits(joint: Joint, worst_load: float) -> JointLimits:
    """``joint``'s limits with the default class in place of an ungiven effort or velocity
    (``worst_load``: the largest gravity load it can carry, N·m or N); given ones stay."""
    limits = joint.limits or JointLimits(lower=None, upper=None, effort=0.0, velocity=0.0)
    effort = limits.effort if limits.effort > 0 else max(
        DEFAULT_EFFORT_FLOOR[joint.type], DEFAULT_EFFORT_MARGIN * abs(worst_load))
    velocity = limits.velocity if limits.velocity > 0 else DEFAULT_VELOCITY[joint.type]
    return replace(limits, effort=float(f"{effort:.3g}"), velocity=velocity)


@dataclass(frozen=True)
class Sizing:
    """A joint's motor and reduction, and what hil assumed in words."""

    joint: str
    motor: MotorClass
    reduction: float
    note: str


def reductions_for(joint: Joint) -> tuple[float, ...]:
    """The reductions a joint of this type may get, smallest first."""
    if joint.type is JointType.PRISMATIC:
        return tuple(2 * math.pi / (lead / 1000) for lead in SCREW_LEADS_MM)
    return tuple(float(n) for n in ROTARY_REDUCTIONS)


def size_joint(joint: Joint, static_load: float = 0.0,
               catalogue: Sequence[MotorClass] = MOTOR_CLASSES) -> Sizing:
    """Motor class and reduction for ``joint`` by the rule of this module; its limits must
    give effort and velocity (> 0); ``static_load`` is the gravity load it holds at rest
    (N·m or N); ``catalogue``: the motors to choose from, smallest first (a protocol's own
    models, :func:`models_catalogue`)."""
    effort, velocity = joint.limits.effort, joint.limits.velocity
    holding = HOLDING_MARGIN * abs(static_load)
    unit = "N" if joint.type is JointType.PRISMATIC else "N·m"
    speed_unit = "m/s" if joint.type is JointType.PRISMATIC else "rad/s"
    limits = (f"joint limits {effort:g} {unit}, {velocity:g} {speed_unit}"
              + (f", gravity load up to {abs(static_load):.3g} {unit}" if static_load else ""))
    for motor in catalogue:
        for reduction in reductions_for(joint):
            if (motor.peak_torque * reduction >= effort and motor.top_speed / reduction >= velocity
                    and motor.rated_torque * reduction >= holding):
                return Sizing(joint.name, motor, reduction, f"{motor.name} motor class "
                              f"(peak {motor.peak_torque:g} N·m, {motor.top_speed:g} rad/s) "
                              f"x {reduction:.4g}; {limits}")
    largest = catalogue[-1]
    candidates = reductions_for(joint)
    reduction = next((n for n in candidates if largest.peak_torque * n >= effort),
                     candidates[-1])
    return Sizing(joint.name, largest, reduction, f"{largest.name} motor class x "
                  f"{reduction:.4g}: no class covers both {limits} (reaches "
                  f"{largest.peak_torque * reduction:.4g} {unit}, "
                  f"{largest.top_speed / reduction:.4g} {speed_unit})")


def models_catalogue(models: Iterable) -> tuple[MotorClass, ...]:
    """A protocol's products (``Protocol.models``' values) as motor classes, smallest peak
    torque first: their figures at the output the drive commands (a geared motor's own gear
    inside: its rotor's inertia as the output feels it, or where its sources give none, a
    ``reflected_inertia`` of 0, :func:`estimated_reflected_inertia` of its ``gear_ratio``)."""
    return tuple(MotorClass(m.name, m.rated_torque, m.peak_torque, m.no_load_speed,
                            m.reflected_inertia or estimated_reflected_inertia(
                                m.rated_torque, m.no_load_speed, m.gear_ratio),
                            inertia_estimated=not m.reflected_inertia)
                 for m in sorted(models, key=lambda m: (m.peak_torque, m.no_load_speed)))


def estimated_reflected_inertia(rated_torque: float, output_speed: float,
                                gear_ratio: float | None) -> float:
    """hil's estimate (kg·m²) of a geared actuator's rotor inertia as its output feels it,
    where its maker publishes none (Robstride, CubeMars, MyActuator): the rotor of the
    smallest generic class (:data:`MOTOR_CLASSES`) whose rated power covers the actuator's,
    rated torque x no-load speed at the output, times the gear ratio squared (0 without a
    gear ratio). Its order of magnitude is the point: tuned on the link's inertia alone
    (no rotor), `hil init`'s MIT gains for a G1's Robstride arms were 150 times softer than
    for its Damiao ones, and the demo ended 0.7 rad off."""
    if not gear_ratio:
        return 0.0
    power = rated_torque * output_speed
    found = next((c for c in MOTOR_CLASSES if c.rated_torque * _CLASS_SPEED >= power),
                 MOTOR_CLASSES[-1])
    return float(f"{found.rotor_inertia * gear_ratio ** 2:.3g}")


def fitting(catalogue: Sequence[MotorClass], peak_torque: float, speed: float) -> MotorClass:
    """The smallest motor of ``catalogue`` that gives ``peak_torque`` and ``speed`` itself
    (a drive whose transmission is the description's), else the largest."""
    return next((m for m in catalogue if m.peak_torque >= peak_torque and m.top_speed >= speed),
                catalogue[-1])
