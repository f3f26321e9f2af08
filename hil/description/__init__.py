"""Robot descriptions: xacro/URDF in, a typed :class:`RobotDescription` out."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from hil.description.model import (
    WORLD, Geometry, GeometryKind, Inertial, Joint, JointDynamics, JointLimits, JointType, Link, Mimic,
    Pose, RobotDescription, TransmissionActuator, TransmissionJoint, TransmissionSpec, Visual,
)
from hil.description.packages import PackagePath, project_robots_dir
from hil.description.source import read_robot_source
from hil.description.urdf import parse_urdf
from hil.description.urdf_transmissions import TRANSMISSION_TYPES
from hil.errors import HilError, Severity

__all__ = [
    "WORLD", "Geometry", "GeometryKind", "Inertial", "Joint", "JointDynamics", "JointLimits", "JointType",
    "Link", "Mimic", "PackagePath", "Pose", "RobotDescription", "TRANSMISSION_TYPES",
    "TransmissionActuator", "TransmissionJoint", "TransmissionSpec", "Visual",
    "load_description", "project_robots_dir",
]


def load_description(path: str | Path, package_path: PackagePath | None = None,
                     strict: bool = False) -> RobotDescription:
    """Load a robot from a .xacro or .urdf file.

    Raises :class:`~hil.errors.HilError` listing every error found (and, with
    ``strict``, every warning too). Warnings are kept in ``.warnings``.
    """
    package_path = package_path or PackagePath.from_environment()
    source = read_robot_source(Path(path), package_path)
    description = parse_urdf(source, package_path)
    if strict and description.warnings:
        raise HilError([replace(w, severity=Severity.ERROR) for w in description.warnings])
    return description
