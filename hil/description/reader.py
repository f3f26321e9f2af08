"""Reading URDF elements while collecting every problem: numbers, vectors, poses, each
problem reported with the file and line where the element is written."""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from pathlib import Path

from hil.description.model import Pose
from hil.description.packages import PackagePath
from hil.description.source import RobotSource
from hil.description.xacro_guard import Allowed
from hil.errors import Diagnostic, error, warning


def start_tag(tag: str, name: str) -> re.Pattern:
    """The start tag ``<tag ... name="name"``, across lines and other attributes."""
    return re.compile(rf"<{re.escape(tag)}\b[^>]*?\bname\s*=\s*[\"']{re.escape(name)}[\"']",
                      re.DOTALL)


class SourceIndex:
    """Finds the file and line where a named element is written.

    The expanded URDF has no line numbers (xacro builds it in memory), so an
    element is found by searching the source files for its start tag with
    the same ``name``. Names built by macros (``${prefix}joint``) are not
    found; the diagnostic then names the top-level file only.
    """

    def __init__(self, files: tuple[Path, ...]):
        self.files = files
        self.texts = {f: f.read_text(errors="replace") for f in files if f.is_file()}

    def locate(self, tag: str, name: str) -> tuple[Path, int | None]:
        pattern = start_tag(tag, name)
        for file, text in self.texts.items():
            match = pattern.search(text)
            if match:
                return file, text.count("\n", 0, match.start()) + 1
        return self.files[0], None


#: the largest mesh file hil reads (hil's limit: a robot's meshes are a few MB each)
MAX_MESH_BYTES = 256 * 1024 * 1024


class ElementReader:
    """One pass over a URDF tree, collecting diagnostics instead of stopping."""

    def __init__(self, source: RobotSource, package_path: PackagePath):
        self.source = source
        self.package_path = package_path
        self.index = SourceIndex(source.files)
        self.diagnostics: list[Diagnostic] = []
        #: fixed/floating joints whose zero axis was ignored (reported once, together)
        self.ignored_axes: list[str] = []
        #: mesh URIs reported missing
        self.missing_meshes: set[str] = set()
        #: mesh URIs found but not read, and why (outside the allowed folders, too large)
        self.refused_meshes: dict[str, str] = {}
        # what a description may reach: its folder or package, the package path
        self._mesh_folders = Allowed.of(source.path, package_path.roots).folders

    def report(self, make, message: str, tag: str, name: str, hint: str | None = None) -> None:
        file, line = self.index.locate(tag, name)
        self.diagnostics.append(make(message, file, line, hint))

    def find_mesh(self, uri: str) -> Path | None:
        """The file a mesh ``filename`` names: ``package://pkg/rel`` on the package path,
        ``file:///abs``, or a path relative to the file that writes it (an included
        file's own folder, not the top file's), else None."""
        if uri.startswith("package://"):
            package, _, rest = uri[len("package://"):].partition("/")
            folder = self.package_path.find(package)
            candidates = [folder / rest] if folder else []
        elif uri.startswith("file://"):
            candidates = [Path(uri[len("file://"):])]
        else:
            writers = [f for f, text in self.index.texts.items() if uri in text]
            candidates = [f.parent / uri for f in (*writers, self.source.path)]
        for candidate in candidates:
            if self._readable_mesh(uri, candidate):
                return candidate
        return None

    def _readable_mesh(self, uri: str, candidate: Path) -> bool:
        """Whether ``candidate`` is a mesh file hil may read; a refusal's reason is kept in
        refused_meshes."""
        try:
            if not candidate.is_file():
                return False
            resolved, size = candidate.resolve(), candidate.stat().st_size
        except OSError:                       # a name the system cannot take (too long)
            return False
        if not any(resolved.is_relative_to(folder) for folder in self._mesh_folders):
            self.refused_meshes[uri] = ("it is outside the description's folder and the "
                                        "package path: hil reads no file there")
            return False
        if size > MAX_MESH_BYTES:
            self.refused_meshes[uri] = f"it is {size} bytes, over hil's {MAX_MESH_BYTES}"
            return False
        return True

    def number(self, text: str | None, what: str, tag: str, name: str,
               default: float | None = None) -> float | None:
        if text is None or text.strip() == "":
            return default
        try:
            value = float(text)
        except ValueError:
            self.report(error, f"{what} '{text}' is not a number", tag, name,
                        hint="write a plain decimal number (xacro expressions need ${...})")
            return default
        if not math.isfinite(value):
            self.report(error, f"{what} is {value}", tag, name, hint="use a finite number")
            return default
        return value

    def vector(self, text: str | None, size: int, what: str, tag: str, name: str,
               default: tuple[float, ...]) -> tuple[float, ...]:
        if text is None:
            return default
        parts = text.replace(",", " ").split()
        if "," in text and len(parts) == size:
            # urdfdom reads '1.57, 0, 0' as three numbers (a stream stops at the comma)
            self.report(warning, f"{tag} '{name}' {what} '{text}' separates its numbers with "
                        f"commas: read as '{' '.join(parts)}'", tag, name,
                        hint="URDF separates numbers with spaces")
        values = [self.number(p, what, tag, name) for p in parts]
        if len(parts) != size or any(v is None for v in values):
            if len(parts) != size:
                self.report(error, f"{what} '{text}' needs {size} numbers", tag, name)
            return default
        return tuple(values)

    def pose(self, element: ET.Element | None, tag: str, name: str) -> Pose:
        if element is None:
            return Pose()
        return Pose(self.vector(element.get("xyz"), 3, "origin xyz", tag, name, (0.0,) * 3),
                    self.vector(element.get("rpy"), 3, "origin rpy", tag, name, (0.0,) * 3))
