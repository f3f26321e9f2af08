"""Typed, immutable robot description: links, joints, transmissions.

This is what the rest of hil sees of a robot; it is built once from URDF
(see :mod:`hil.description.urdf`) and never holds raw XML.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

from hil.errors import Diagnostic

Vec3 = tuple[float, float, float]
#: a root link of this name is the fixed world (UR, xArm, Unitree arms ...), not a body
WORLD = "world"


@dataclass(frozen=True)
class Pose:
    """A URDF ``<origin>``: translation in metres, roll-pitch-yaw in radians."""

    xyz: Vec3 = (0.0, 0.0, 0.0)
    rpy: Vec3 = (0.0, 0.0, 0.0)

    @property
    def distance(self) -> float:
        return math.sqrt(sum(c * c for c in self.xyz))


@dataclass(frozen=True)
class Inertial:
    """Mass (kg), centre of mass frame and inertia tensor (kg m^2) about it."""

    mass: float
    origin: Pose
    ixx: float
    ixy: float
    ixz: float
    iyy: float
    iyz: float
    izz: float

    def equivalent_box(self) -> Vec3:
        """Edge lengths (x, y, z) of the uniform box with this mass and inertia.

        hil draws links whose meshes are missing as this box at the centre of
        mass: it has the link's size and proportions without any mesh data.
        Off-diagonal terms are ignored; a degenerate axis gets 1 cm.
        """
        mass = max(self.mass, 1e-9)
        ixx, iyy, izz = self.ixx, self.iyy, self.izz
        squares = (6 * (iyy + izz - ixx) / mass, 6 * (ixx + izz - iyy) / mass,
                   6 * (ixx + iyy - izz) / mass)
        return tuple(max(math.sqrt(max(s, 0.0)), 0.01) for s in squares)


class GeometryKind(enum.Enum):
    BOX = "box"
    CYLINDER = "cylinder"
    SPHERE = "sphere"
    MESH = "mesh"
    #: a scene's ground (never in a URDF): the plane z = 0 of its pose, endless
    PLANE = "plane"


@dataclass(frozen=True)
class Geometry:
    """A visual or collision shape.

    ``size`` is (x, y, z) for a box, (radius, length) for a cylinder, (radius,)
    for a sphere and the mesh scale for a mesh. ``mesh`` is the resolved file,
    or None when the mesh could not be found (then ``kind`` is a primitive
    stand-in and ``missing_mesh`` keeps the original URI).
    """

    kind: GeometryKind
    size: tuple[float, ...]
    mesh: Path | None = None
    missing_mesh: str | None = None


@dataclass(frozen=True)
class Visual:
    origin: Pose
    geometry: Geometry
    rgba: tuple[float, float, float, float] | None = None


@dataclass(frozen=True)
class Collision:
    """A ``<collision>`` shape: what the link touches the scene with (a mesh as its convex
    hull)."""

    origin: Pose
    geometry: Geometry


@dataclass(frozen=True)
class Link:
    name: str
    inertial: Inertial | None = None
    visuals: tuple[Visual, ...] = ()
    collisions: tuple[Collision, ...] = ()


class JointType(enum.Enum):
    REVOLUTE = "revolute"
    CONTINUOUS = "continuous"
    PRISMATIC = "prismatic"
    FIXED = "fixed"
    FLOATING = "floating"
    PLANAR = "planar"

    @property
    def is_rotational(self) -> bool:
        return self in (JointType.REVOLUTE, JointType.CONTINUOUS)

    @property
    def unit(self) -> str:
        return "m" if self is JointType.PRISMATIC else "rad"

    @property
    def effort_unit(self) -> str:
        return "N" if self is JointType.PRISMATIC else "N·m"


@dataclass(frozen=True)
class JointLimits:
    """``<limit>``: position range (None for continuous joints), effort, velocity."""

    lower: float | None
    upper: float | None
    effort: float
    velocity: float


@dataclass(frozen=True)
class JointDynamics:
    """``<dynamics>``: viscous damping and Coulomb friction, joint side."""

    damping: float = 0.0
    friction: float = 0.0


@dataclass(frozen=True)
class Mimic:
    """``<mimic>``: q = multiplier * q_leader + offset."""

    joint: str
    multiplier: float = 1.0
    offset: float = 0.0


@dataclass(frozen=True)
class Joint:
    name: str
    type: JointType
    parent: str
    child: str
    origin: Pose = Pose()
    axis: Vec3 = (1.0, 0.0, 0.0)
    limits: JointLimits | None = None
    dynamics: JointDynamics = JointDynamics()
    mimic: Mimic | None = None

    @property
    def is_movable(self) -> bool:
        return self.type in (JointType.REVOLUTE, JointType.CONTINUOUS, JointType.PRISMATIC)


@dataclass(frozen=True)
class TransmissionJoint:
    """A joint's side of a transmission (ros2_control ``<joint>`` in ``<transmission>``)."""

    name: str
    role: str | None = None
    reduction: float = 1.0
    offset: float = 0.0


@dataclass(frozen=True)
class TransmissionActuator:
    """An actuator's side of a transmission.

    ``rotor_inertia`` (kg m^2, motor side) is a hil extension: the plant adds
    it as reflected inertia. ROS tools ignore the element.
    """

    name: str
    role: str | None = None
    reduction: float = 1.0
    rotor_inertia: float = 0.0


#: Transmission types hil can model, by ros2_control's names for them. A type is read by its
#: last part, so ROS 1's (``pr2_mechanism_model/SimpleTransmission``, a bare
#: ``SimpleTransmission``) name the same ones.
TRANSMISSION_TYPES = {
    "transmission_interface/SimpleTransmission": "simple",
    "transmission_interface/DifferentialTransmission": "differential",
    "transmission_interface/FourBarLinkageTransmission": "four_bar",
}

@dataclass(frozen=True)
class TransmissionSpec:
    """A ``<transmission>`` as written in the URDF; turned into maps by
    :func:`hil.transmissions.build_transmission`."""

    name: str
    type: str
    joints: tuple[TransmissionJoint, ...]
    actuators: tuple[TransmissionActuator, ...]


@dataclass(frozen=True)
class RobotDescription:
    """A whole robot, validated. Joints are in URDF order."""

    name: str
    source: Path
    links: tuple[Link, ...]
    joints: tuple[Joint, ...]
    transmissions: tuple[TransmissionSpec, ...]
    warnings: tuple[Diagnostic, ...] = field(default=(), compare=False)
    #: the files it was read from (the top one first, then xacro's includes)
    files: tuple[Path, ...] = field(default=(), compare=False)

    def link(self, name: str) -> Link:
        return self._links_by_name[name]

    def joint(self, name: str) -> Joint:
        return self._joints_by_name[name]

    @cached_property
    def _links_by_name(self) -> dict[str, Link]:
        return {link.name: link for link in self.links}

    @cached_property
    def _joints_by_name(self) -> dict[str, Joint]:
        return {joint.name: joint for joint in self.joints}

    @property
    def root_link(self) -> str:
        children = {j.child for j in self.joints}
        return next(link.name for link in self.links if link.name not in children)

    @property
    def movable_joints(self) -> tuple[Joint, ...]:
        return tuple(j for j in self.joints if j.is_movable)

    @property
    def driven_joints(self) -> tuple[Joint, ...]:
        """Joints moved by an actuator through a transmission, in URDF order."""
        names = {tj.name for t in self.transmissions for tj in t.joints}
        return tuple(j for j in self.joints if j.name in names)

    @property
    def undriven_joints(self) -> tuple[Joint, ...]:
        """Movable joints that no transmission drives and that follow no other (mimic): the
        joints ``hil init`` gives a drive each, in URDF order."""
        driven = {tj.name for t in self.transmissions for tj in t.joints}
        return tuple(j for j in self.joints
                     if j.is_movable and j.mimic is None and j.name not in driven)

    @property
    def actuators(self) -> tuple[TransmissionActuator, ...]:
        return tuple(a for t in self.transmissions for a in t.actuators)

    def reduction(self, actuator: str) -> float:
        """Joint to motor of ``actuator``'s transmission: the radians its motor turns per
        radian (or metre) of its first joint; KeyError for an actuator no transmission has."""
        for transmission in self.transmissions:
            if actuator in (a.name for a in transmission.actuators):
                return transmission.actuators[0].reduction * transmission.joints[0].reduction
        raise KeyError(actuator)

    @property
    def total_mass(self) -> float:
        return sum(link.inertial.mass for link in self.links if link.inertial)

    def children_of(self, link: str) -> tuple[Joint, ...]:
        return tuple(j for j in self.joints if j.parent == link)
