"""Shared fixtures: the seed robots, the bad-input corpus, a package path."""

from __future__ import annotations

from pathlib import Path

import pytest

from hil.description import PackagePath, load_description

TESTS = Path(__file__).resolve().parent
ROOT = TESTS.parent
UR3_XACRO = ROOT / "robots" / "ur3_description" / "urdf" / "ur3.xacro"
PIGOT_XACRO = ROOT / "robots" / "pigot_description" / "urdf" / "pigot.xacro"
CORPUS = TESTS / "corpus"
COUPLED_URDF = TESTS / "fixtures" / "coupled_transmissions.urdf"


@pytest.fixture(scope="session")
def package_path() -> PackagePath:
    """The corpus folder first, then robots/ (no environment influence)."""
    return PackagePath((CORPUS, ROOT / "robots"))


@pytest.fixture(scope="session")
def ur3(package_path):
    return load_description(UR3_XACRO, package_path)


@pytest.fixture(scope="session")
def pigot(package_path):
    return load_description(PIGOT_XACRO, package_path)


@pytest.fixture(scope="session")
def coupled(package_path):
    return load_description(COUPLED_URDF, package_path)
