"""Reading a robot's XML: xacro expansion and well-formedness, with errors
that name the file, the line and what to do.

xacro (the PyPI package, ROS 2's xacro) does the expansion, guarded so that a description
runs no code and reads nothing outside what the user allowed
(:mod:`hil.description.xacro_guard`); this module translates its failures into
:class:`~hil.errors.ConfigError` and records which files took part, so later checks can point
at lines in them.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
import xml.parsers.expat
from dataclasses import dataclass
from pathlib import Path

from hil.description.packages import AmentPrefix, PackagePath
from hil.description.xacro_guard import Allowed, guarded
from hil.errors import ConfigError, Diagnostic, error, warning
from hil.input_files import read_input_file


@dataclass(frozen=True)
class RobotSource:
    """The expanded URDF of a robot, parsed, and the files it came from."""

    path: Path
    root: ET.Element
    files: tuple[Path, ...]
    #: what was corrected in the main file's text before parsing (warnings)
    corrections: tuple[Diagnostic, ...] = ()


#: namespaces hil knows by prefix; any other prefix a file uses without declaring it is
#: declared with a placeholder (its attributes mean nothing to hil)
KNOWN_NAMESPACES = {"xacro": "http://www.ros.org/wiki/xacro"}


def lenient_text(path: Path, text: str) -> tuple[str, list[Diagnostic]]:
    """``text`` with the defects ROS tools read past corrected, each a warning naming the
    line: blank lines before the XML declaration, NUL bytes, namespace prefixes used but
    never declared (``drake:acceleration="..."``)."""
    corrections = []

    def line_of(position: int) -> int:          # in the file as it is on disk
        return text.count("\n", 0, position) + 1

    if "\0" in text:
        corrections.append(warning(f"{text.count(chr(0))} NUL byte(s) in the file: removed",
                                   path, line_of(text.index("\0")),
                                   hint="save the file as plain UTF-8 text"))
    declared = set(re.findall(r"xmlns:([\w.-]+)\s*=", text)) | {"xml", "xmlns"}
    used: dict[str, int] = {}
    for match in re.finditer(r"[<\s]([A-Za-z_][\w.-]*):[A-Za-z_][\w.-]*", _markup(text)):
        if match.group(1) not in declared:
            used.setdefault(match.group(1), line_of(match.start() + 1))
    for prefix, line in used.items():
        corrections.append(warning(
            f"namespace prefix '{prefix}:' is used but never declared: declared for you",
            path, line, hint=f"add xmlns:{prefix}=\"...\" to <robot>"))
    start = len(text) - len(text.lstrip())
    if start and text.lstrip().startswith("<?xml"):
        corrections.append(warning(
            f"{line_of(start) - 1} blank line(s) before the XML declaration, which XML "
            "allows only at the very start: removed", path, 1,
            hint="start the file with <?xml ...?>"))
    else:
        start = 0
    text = text[start:].replace("\0", "")
    root = re.search(r"<robot\b", text)
    if used and root:
        text = text[:root.end()] + "".join(
            f' xmlns:{prefix}="{KNOWN_NAMESPACES.get(prefix, "urn:hil:undeclared:" + prefix)}"'
            for prefix in used) + text[root.end():]
    return text, corrections


def _markup(text: str) -> str:
    """``text`` with comments, text between tags and attribute values blanked out (same
    length): only tag and attribute names are left to look at."""
    blanked = re.sub(r"<!--.*?-->|<\?.*?\?>", lambda m: " " * len(m.group()), text,
                     flags=re.DOTALL)
    blanked = re.sub(r'"[^"]*"|\'[^\']*\'', lambda m: " " * len(m.group()), blanked)
    return re.sub(r">[^<]*<", lambda m: ">" + " " * (len(m.group()) - 2) + "<", blanked)


def read_robot_source(path: Path, package_path: PackagePath) -> RobotSource:
    """Expand ``path`` (.xacro, or plain .urdf) into URDF text."""
    path = Path(path)
    text, corrections = lenient_text(path.resolve(), read_input_file(
        path, "robot description", hint="give the path of a .urdf or .xacro file",
        syntax="xml"))
    if path.suffix == ".urdf":
        try:
            root = ET.fromstring(text)
        except ET.ParseError as exc:
            line, column = exc.position
            raise _xml_error(path, text, line, column, str(exc).split(":")[0]) from None
        return RobotSource(path, root, (path.resolve(),), tuple(corrections))
    return _expand_xacro(path, package_path, text if corrections else None,
                         tuple(corrections))


def _xml_error(path: Path, text: str, lineno: int, offset: int, reason: str) -> ConfigError:
    """Explain an XML syntax error, recognising the seeds' common defects: a comment inside
    a start tag is reported with every other one in the file, so that one run finds all."""
    lines = text.splitlines()
    line = lines[lineno - 1] if 0 < lineno <= len(lines) else ""
    if line[offset:].startswith("<!--"):
        return ConfigError([error(
            f"XML comment inside the start tag of <{tag}> (column {column}): "
            "XML allows comments only between tags, not between attributes", path, number,
            hint=f"move the comment after the '>' that closes <{tag} ...>, "
                 "e.g. <joint name=\"j\" type=\"revolute\">  <!-- note -->")
            for number, column, tag in comments_in_start_tags(text)])
    return ConfigError.single(f"malformed XML: {reason} (column {offset + 1})", path, lineno,
                              hint="fix the XML syntax at that position")


def comments_in_start_tags(text: str) -> list[tuple[int, int, str]]:
    """(line, column, tag) of every ``<!--`` written inside a start tag."""
    found = []
    blanked = re.sub(r"<!--.*?-->", lambda m: " " * len(m.group()), text, flags=re.DOTALL)
    for match in re.finditer(r"<!--.*?-->", text, re.DOTALL):
        # the markup this comment sits in: the last '<' or '>' before it, outside comments
        before = blanked[:match.start()]
        opened, closed = before.rfind("<"), before.rfind(">")
        start = re.match(r"<([A-Za-z_][\w:.-]*)", before[opened:]) if opened > closed else None
        if start:
            found.append((text.count("\n", 0, match.start()) + 1,
                          match.start() - text.rfind("\n", 0, match.start()), start.group(1)))
    return found


def _expand_xacro(path: Path, package_path: PackagePath, corrected: str | None,
                  corrections: tuple[Diagnostic, ...]) -> RobotSource:
    """Expand with xacro; ``corrected``: the main file's text to expand instead of the
    file's own (lenient_text changed it)."""
    import xacro  # imported here: its import is slow and plain URDF does not need it

    known_includes = len(xacro.all_includes)
    # Paths are resolved inside the block: the prefix's package links vanish after it. No
    # expression runs code and no file outside the description's folder and the package
    # path is read (hil.description.xacro_guard).
    with AmentPrefix(package_path), guarded(Allowed.of(path, package_path.roots)):
        try:
            if corrected is None:
                doc = xacro.process_file(str(path))
            else:       # xacro.process_file, on the corrected text
                xacro.init_stacks(str(path))
                doc = xacro.parse(corrected, str(path))
                xacro.process_doc(doc)
        except xml.parsers.expat.ExpatError as exc:
            failing = Path(xacro.filestack[-1] or path).resolve()
            raise _xml_error(failing, failing.read_text(errors="replace"), exc.lineno,
                             exc.offset, xml.parsers.expat.ErrorString(exc.code)) from None
        except xacro.XacroException as exc:
            current = Path(xacro.filestack[-1] or path).resolve() if xacro.filestack else path
            raise _xacro_error(exc, current, package_path) from None
        except RecursionError:
            raise ConfigError.single("xacro expansion nests without end (a macro that calls "
                                     "itself, or includes that include each other?)", path,
                                     hint="give each recursive macro a condition that ends "
                                          "it") from None
        includes = [Path(p).resolve() for p in xacro.all_includes[known_includes:]]
    files = tuple(dict.fromkeys((path.resolve(), *includes)))
    return RobotSource(path, ET.fromstring(doc.toxml()), files, corrections)


def _xacro_error(exc, current: Path, package_path: PackagePath) -> ConfigError:
    cause = exc.exc
    if type(cause).__name__ == "PackageNotFoundError":
        package = re.search(r"'([^']+)'", str(cause))
        name = package.group(1) if package else str(cause)
        return ConfigError.single(
            f"$(find {name}): no package named '{name}' on the package search path "
            f"({package_path.describe()})",
            current, first_line_of(current, f"$(find {name})"),
            hint=f"add the folder that contains '{name}' with --package-path DIR "
                 f"or the HIL_PACKAGE_PATH environment variable")
    if isinstance(cause, OSError) and getattr(cause, "filename", None):
        missing = Path(cause.filename)
        return ConfigError.single(
            f"included file '{missing}' does not exist",
            current, first_line_of(current, missing.name),
            hint="fix the <xacro:include filename=...> or add the missing file")
    line = _xacro_line(str(exc), current)
    return ConfigError.single(f"xacro: {' '.join(str(exc).split())}", current, line,
                              hint="fix the xacro at that line" if line else
                              "fix the xacro at the named file")


#: what each kind of xacro error names, and how that appears in the file
_XACRO_NEEDLES = (
    (r"when evaluating expression '(.+?)'", lambda m: re.escape(m)),
    (r"name '(\w+)' is not defined", lambda m: rf"\$\{{[^}}]*\b{m}\b"),
    (r"unknown macro name: (\S+)", lambda m: rf"<{re.escape(m)}\b"),
    (r"Undefined parameters \[([^\],]+)", lambda m: rf"params=[\"'][^\"']*\b{m}\b"),
    (r"Undefined substitution argument (\S+)", lambda m: rf"\$\(arg {re.escape(m)}\)"),
)


def _xacro_line(message: str, file: Path) -> int | None:
    """The line of ``file`` where what a xacro error names is written, if it can be found."""
    try:
        text = file.read_text(errors="replace")
    except OSError:
        return None
    for named, written in _XACRO_NEEDLES:
        match = re.search(named, message)
        found = match and re.search(written(match.group(1)), text)
        if found:
            return text.count("\n", 0, found.start()) + 1
    return None


def first_line_of(path: Path, needle: str) -> int | None:
    """The first line of ``path`` that holds ``needle`` (None if none does, or no file)."""
    try:
        for number, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
            if needle in line:
                return number
    except OSError:
        pass
    return None
