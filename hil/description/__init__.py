"""Robot descriptions: xacro/URDF in, a typed :class:`RobotDescription` out.

The model's types import nothing heavy; :func:`load_description` (with xacro and the URDF
reader) and :class:`PackagePath` (the
package look-up of ``$(find)`` and ``package://``) load on first use.
"""

from __future__ import annotations

from hil.description.model import (
    TRANSMISSION_TYPES, WORLD, Collision, Geometry, GeometryKind, Inertial, Joint, JointDynamics,
    JointLimits, JointType, Link, Mimic, Pose, RobotDescription, TransmissionActuator,
    TransmissionJoint, TransmissionSpec, Visual,
)
from hil.lazy import lazy_exports

__getattr__ = lazy_exports(__name__, {
    "load_description": "hil.description.load", "PackagePath": "hil.description.packages",
    "project_robots_dir": "hil.description.packages"})

__all__ = [
    "WORLD", "Collision", "Geometry", "GeometryKind", "Inertial", "Joint", "JointDynamics",
    "JointLimits", "JointType",
    "Link", "Mimic", "PackagePath", "Pose", "RobotDescription", "TRANSMISSION_TYPES",
    "TransmissionActuator", "TransmissionJoint", "TransmissionSpec", "Visual",
    "load_description", "project_robots_dir",
]
