"""Loading a robot description: xacro expanded, URDF read, every problem reported."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from hil.description.model import RobotDescription
from hil.description.packages import PackagePath
from hil.description.source import read_robot_source
from hil.description.urdf import parse_urdf
from hil.errors import ConfigError, Severity


def load_description(path: str | Path, package_path: PackagePath | None = None,
                     strict: bool = False) -> RobotDescription:
    """Load a robot from a .xacro or .urdf file.

    Raises :class:`~hil.errors.ConfigError` listing every error found (and, with
    ``strict``, every warning too). Warnings are kept in ``.warnings``.
    """
    package_path = package_path or PackagePath.from_environment()
    source = read_robot_source(Path(path), package_path)
    description = parse_urdf(source, package_path)
    if strict and description.warnings:
        raise ConfigError([replace(w, severity=Severity.ERROR) for w in description.warnings])
    return description
