"""Finding ROS-style description packages without ROS.

Robots refer to their files as ``$(find pkg)/urdf/x.xacro`` (xacro) and
``package://pkg/meshes/x.stl`` (URDF). hil resolves both from a *package
search path*: folders given with ``--package-path``, then ``$HIL_PACKAGE_PATH``
(and ``$ROS_PACKAGE_PATH`` if set), then this project's ``robots/`` folder.
A package is a folder holding a ``package.xml`` (its ``<name>`` names it), or
any folder directly inside a search-path entry.

xacro resolves ``$(find pkg)`` through the ament resource index
(``ament_index_python``), the supported way in ROS 2. hil therefore publishes
its search path as an ament prefix (a folder with ``share/<pkg>`` links and
the ``share/ament_index/resource_index/packages/<pkg>`` markers) on
``$AMENT_PREFIX_PATH``. Where ROS is installed its own ``ament_index_python``
reads that prefix; where it is not, :func:`_install_ament_index_lookup`
registers a minimal reader of the same file layout, because
``ament_index_python`` is not published on PyPI.
"""

from __future__ import annotations

import atexit
import functools
import importlib.util
import os
import shutil
import sys
import tempfile
import types
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from hil.errors import HilError
from hil.input_files import read_input_file
from hil.resources import ROBOTS, data_dir

PACKAGE_PATH_ENV = "HIL_PACKAGE_PATH"
_MAX_DEPTH = 3
_RESOURCE_DIR = Path("share") / "ament_index" / "resource_index" / "packages"


def own_package(path: Path) -> Path | None:
    """The ROS package folder holding ``path``: the nearest folder above it with a
    package.xml (None: in no package)."""
    for folder in Path(path).resolve().parents:
        if (folder / "package.xml").is_file():
            return folder
    return None


def project_robots_dir() -> Path:
    """The ``robots/`` folder shipped with hil."""
    return data_dir(ROBOTS)


@dataclass(frozen=True)
class PackagePath:
    """An ordered list of folders to search for description packages."""

    roots: tuple[Path, ...]

    def __post_init__(self):
        object.__setattr__(self, "roots", tuple(Path(root) for root in self.roots))

    @classmethod
    def from_environment(cls, extra: list[str] | tuple[str, ...] = ()) -> "PackagePath":
        """``extra`` (e.g. from ``--package-path``) first, then the environment, then robots/."""
        roots: list[Path] = [Path(p) for p in extra]
        for env in (PACKAGE_PATH_ENV, "ROS_PACKAGE_PATH"):
            roots += [Path(p) for p in os.environ.get(env, "").split(os.pathsep) if p]
        roots.append(project_robots_dir())
        unique = dict.fromkeys(r.expanduser().resolve() for r in roots)
        return cls(tuple(unique))

    @functools.cached_property
    def _found(self) -> dict[str, Path]:
        found: dict[str, Path] = {}
        for root in self.roots:
            if not root.is_dir():
                continue
            for name, folder in _packages_under(root):
                found.setdefault(name, folder)
        return found

    def packages(self) -> dict[str, Path]:
        """Package name -> folder; the first root that has a package wins. A package is
        found by its package.xml ``<name>`` and by its folder's name (descriptions use
        either in ``package://``); the folders are read once."""
        return dict(self._found)

    def find(self, package: str) -> Path | None:
        return self._found.get(package)

    def describe(self) -> str:
        return os.pathsep.join(str(r) for r in self.roots)


def _packages_under(root: Path):
    for child in sorted(root.iterdir()):
        if child.is_dir() and not (child / "package.xml").exists():
            yield child.name, child
    for manifest in sorted(_manifests(root, 0)):
        yield _manifest_name(manifest), manifest.parent
        yield manifest.parent.name, manifest.parent


def _manifests(folder: Path, depth: int):
    # any package.xml marks a package, as in _packages_under: one that is no regular file
    # leaves it its folder's name (_manifest_name), where is_file() lost the package
    if (folder / "package.xml").exists():
        yield folder / "package.xml"
        return
    if depth >= _MAX_DEPTH:
        return
    for child in folder.iterdir():
        if child.is_dir() and not child.name.startswith("."):
            yield from _manifests(child, depth + 1)


def _manifest_name(manifest: Path) -> str:
    """The ``<name>`` of a package.xml (REP 149), read as every named file is (bounded, no
    DOCTYPE: its entities could name the package anything, or expand without end); where it
    cannot be read or gives none, the folder's name (hil's choice: the package is still
    found by its folder, as the module doc says)."""
    try:
        text = read_input_file(manifest, "package manifest", "fix or remove the package.xml",
                               syntax="xml")
        name = ET.fromstring(text).findtext("name")
    except (HilError, ET.ParseError):
        name = None
    return (name or manifest.parent.name).strip()


class AmentPrefix:
    """A temporary ament prefix publishing a :class:`PackagePath` for xacro.

    Use as a context manager: while active, ``$AMENT_PREFIX_PATH`` starts
    with the prefix, so ``$(find pkg)`` finds the search path's packages.
    """

    def __init__(self, package_path: PackagePath):
        self.package_path = package_path
        self._prefix: Path | None = None
        self._saved_env: str | None = None

    def __enter__(self) -> "AmentPrefix":
        _install_ament_index_lookup()
        self._prefix = Path(tempfile.mkdtemp(prefix="hil-ament-"))
        atexit.register(shutil.rmtree, self._prefix, True)
        markers = self._prefix / _RESOURCE_DIR
        markers.mkdir(parents=True)
        for name, folder in self.package_path.packages().items():
            link = self._prefix / "share" / name
            if link.exists() or link.is_symlink():     # e.g. a folder named ament_index
                continue
            (markers / name).touch()
            link.symlink_to(folder.resolve(), target_is_directory=True)   # a relative root
        self._saved_env = os.environ.get("AMENT_PREFIX_PATH")
        os.environ["AMENT_PREFIX_PATH"] = os.pathsep.join(
            p for p in (str(self._prefix), self._saved_env) if p)
        return self

    def __exit__(self, *exc) -> None:
        if self._saved_env is None:
            os.environ.pop("AMENT_PREFIX_PATH", None)
        else:
            os.environ["AMENT_PREFIX_PATH"] = self._saved_env
        if self._prefix is not None:
            shutil.rmtree(self._prefix, ignore_errors=True)


class PackageNotFoundError(KeyError):
    """Raised by the stand-in ament lookup, as ament_index_python does."""


def _get_package_share_directory(package_name: str, print_warning: bool = True) -> str:
    """The ament resource index lookup: first prefix with the marker wins."""
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        if prefix and (Path(prefix) / _RESOURCE_DIR / package_name).is_file():
            return str(Path(prefix) / "share" / package_name)
    raise PackageNotFoundError(f"package '{package_name}' not found")


def _install_ament_index_lookup() -> None:
    """Provide ``ament_index_python.packages`` where ROS does not."""
    if "ament_index_python" in sys.modules or importlib.util.find_spec("ament_index_python"):
        return
    package = types.ModuleType("ament_index_python")
    packages = types.ModuleType("ament_index_python.packages")
    packages.get_package_share_directory = _get_package_share_directory
    packages.PackageNotFoundError = PackageNotFoundError
    package.packages = packages
    package.PackageNotFoundError = PackageNotFoundError
    sys.modules["ament_index_python"] = package
    sys.modules["ament_index_python.packages"] = packages
