"""Reading a file a user names (a bus config, a robot description, a trajectory, a Zenoh
config, an EDS, a log): a regular file of bounded size, UTF-8 where it is text, nested no
deeper than a file of its kind needs, or a clear error naming the file. Every reader of a
named file goes through here before its parser sees the file: one that streams it (a CAN
log, a recording: gigabytes) is handed the checked file open (open_input_stream), any other
reads it whole (read_input_bytes, read_input_file: the same open, then the bytes).

What each check stops: a FIFO waits for a writer without end and a device (``/dev/zero``)
fills the memory, so the file's kind is checked on a descriptor opened without blocking,
before a byte is read; a file of gigabytes is no input; a document nested 50,000 deep
overflows the stack of a recursive parser (Python's ``json``: RecursionError; Zenoh's
JSON5 parser in Rust: SIGSEGV, measured 2026-12-06), so the depth is counted by a scan that
does not recurse, before the parser runs; an XML document type declaration declares
entities that expand without bound (the "billion laughs"), and no file hil reads needs
one, so it is refused (as defusedxml's ``forbid_dtd`` does; defusedxml is not a dependency).
"""

from __future__ import annotations

import codecs
import errno
import os
import re
import stat
import xml.parsers.expat
from pathlib import Path
from typing import BinaryIO, Literal

import yaml

from hil.errors import ConfigError, HilError

#: the largest input file hil reads (bytes), where its reader names no other limit
MAX_FILE_BYTES = 16 * 1024 * 1024
#: the deepest nesting of a JSON, YAML or XML input: a bus config, a Zenoh config, a
#: trajectory or a description nests a dozen levels at most (hil's choice, with room)
MAX_NESTING = 100
#: the longest name of one path component Linux takes (NAME_MAX, bytes)
NAME_MAX = 255

Syntax = Literal["json", "yaml", "xml"]


def open_input_stream(path: os.PathLike | str, what: str, hint: str,
                      limit: int = MAX_FILE_BYTES) -> BinaryIO:
    """``path`` (a ``what``: "CAN log", "bus config", ...) open for reading in binary, for a
    reader that streams it (a log, a recording) or reads it whole (read_input_bytes);
    ConfigError naming it where it is missing, no regular file, over ``limit`` bytes, or cannot
    be opened (``hint``: what to do). The descriptor checked is the one read, so nothing can
    be put in the file's place between the check and the read."""
    path = Path(path)
    try:
        # O_NONBLOCK: opening a FIFO with no writer returns at once instead of waiting
        descriptor = os.open(path, os.O_RDONLY | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError as exc:
        raise _refused(path, what, hint, _os_problem(path, exc)) from None
    try:
        problem = _status_problem(os.fstat(descriptor), limit)    # the file that is read
        if problem is None:
            os.set_blocking(descriptor, True)       # a regular file: read as any file is
            return os.fdopen(descriptor, "rb")
    except OSError as exc:
        problem = _os_problem(path, exc)
    os.close(descriptor)
    raise _refused(path, what, hint, problem)


def read_input_bytes(path: Path, what: str, hint: str, limit: int = MAX_FILE_BYTES) -> bytes:
    """The bytes of ``path`` (a ``what``: "bus config", ...) as open_input_stream opens it;
    ConfigError naming the file where it is missing, no regular file, over ``limit`` bytes, or
    cannot be read."""
    path = Path(path)
    with open_input_stream(path, what, hint, limit) as file:
        try:
            data = file.read(limit + 1)              # a file that grew since: still bounded
        except OSError as exc:
            raise _refused(path, what, hint, _os_problem(path, exc)) from None
    if len(data) > limit:
        raise _refused(path, what, hint, f"is over the {limit} bytes hil reads")
    return data


def file_problem(path: Path, limit: int = MAX_FILE_BYTES) -> str | None:
    """Why ``path`` is no regular file of at most ``limit`` bytes ("does not exist", "is
    not a regular file", ...), or None: for a file a library opens by its name (a mesh
    MuJoCo reads), checked before the name is handed over."""
    path = Path(path)
    try:
        return _status_problem(os.stat(path), limit)
    except OSError as exc:
        return _os_problem(path, exc)


def read_input_file(path: Path, what: str, hint: str, limit: int = MAX_FILE_BYTES,
                    syntax: Syntax | None = None) -> str:
    """The text of ``path`` as read_input_bytes reads it, decoded as UTF-8 (a byte order
    mark dropped): ConfigError naming the line of the first byte that is not UTF-8. With a
    ``syntax``, its nesting checked (check_nesting) before anything parses it."""
    path = Path(path)
    data = read_input_bytes(path, what, hint, limit)
    try:
        text = data.decode(_declared_encoding(data) if syntax == "xml" else "utf-8-sig")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise ConfigError.single(f"{what} is not UTF-8 text: byte 0x{data[exc.start]:02X} "
                              f"cannot start or continue a character", path, line,
                              hint=f"save the {what} as UTF-8 text") from None
    if syntax is not None:
        check_nesting(text, syntax, path, what)
    return text


def refusal_text(refused: HilError) -> str:
    """What a reader here refused, as one phrase (``trajectory is nested more than 100 deep
    (goal.json:2)``), for a caller that reports it in its own words: a library's exception,
    the line of the config that named the file."""
    said = refused.diagnostics[0]
    return said.message + (f" ({said.location})" if said.file else "")


#: an XML declaration's encoding (XML 1.0, 4.3.3: a document not in UTF-8 says which)
_XML_ENCODING = re.compile(rb'^\s*<\?xml[^>]*?encoding\s*=\s*["\']([A-Za-z0-9._-]{1,40})["\']')


def _declared_encoding(data: bytes) -> str:
    """The encoding an XML document declares (a CAD exporter's URDF in ISO-8859-1), where
    Python knows it; else UTF-8 (a byte order mark dropped)."""
    declared = _XML_ENCODING.match(data)
    if declared:
        try:
            return codecs.lookup(declared.group(1).decode("ascii")).name
        except LookupError:
            pass
    return "utf-8-sig"


def check_nesting(text: str, syntax: Syntax, path: Path, what: str,
                  limit: int = MAX_NESTING) -> None:
    """ConfigError with the line where ``text`` (JSON or JSON5, YAML, or XML) nests deeper than
    ``limit``; for XML, also where it declares a document type (entities). Counted without
    recursion: only the parser that runs after may recurse. Text the scan cannot read is
    left to that parser, which names the syntax error better."""
    if syntax == "xml":
        found = _xml_problem(text, limit)
    else:
        line = (_yaml_too_deep if syntax == "yaml" else _json_too_deep)(text, limit)
        found = None if line is None else (line, False)
    if found is None:
        return
    line, doctype = found
    if doctype:
        raise ConfigError.single(f"{what} declares an XML document type (<!DOCTYPE ...>)", path,
                              line, hint="remove the <!DOCTYPE ...>: hil reads no document "
                                         "type declaration (its entities can expand without "
                                         "end)")
    raise ConfigError.single(f"{what} is nested more than {limit} deep", path, line,
                          hint=f"flatten it: a {what} nests a dozen levels at most")


def _status_problem(status: os.stat_result, limit: int) -> str | None:
    if stat.S_ISDIR(status.st_mode):
        return "is a folder"
    if not stat.S_ISREG(status.st_mode):
        return "is not a regular file (a FIFO, a device, a socket)"
    if status.st_size > limit:
        return _over_limit(status.st_size, limit)
    return None


#: the units a size is given in, largest first
_UNITS = (("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10))


def size_in_words(count: int) -> str:
    """A size as people read it: ``512 bytes``, ``3.2 MiB``, ``4 GiB``."""
    for unit, scale in _UNITS:
        if count >= scale:
            return f"{count / scale:.3g} {unit}"
    return f"{count} bytes"


def _over_limit(size: int, limit: int) -> str:
    """``is 4.88 KiB, over the 4 KiB hil reads``: the size in the unit the limit is a whole
    number of, so the two compare at a glance (in bytes where rounding would hide the
    difference: 4097 bytes is no "4 KiB, over the 4 KiB")."""
    unit, scale = next(((unit, scale) for unit, scale in _UNITS
                        if limit >= scale and limit % scale == 0), ("bytes", 1))
    most = f"{limit // scale} {unit}" if scale > 1 else f"{limit}"    # "bytes" said before
    shown = f"{size / scale:.3g}"
    if scale > 1 and float(shown) * scale > limit:
        return f"is {shown} {unit}, over the {most} hil reads"
    return f"is {size} bytes, over the {most} hil reads"


def _os_problem(path: Path, exc: OSError) -> str:
    if exc.errno == errno.ENOENT:
        return "does not exist"
    if exc.errno == errno.ENAMETOOLONG:
        longest = max((len(os.fsencode(part)) for part in path.parts), default=0)
        return (f"has a name of {longest} bytes, over the {NAME_MAX} a file name may have"
                if longest > NAME_MAX else
                f"is {len(os.fsencode(path))} bytes long, longer than the system takes")
    return f"cannot be read: {exc.strerror}"


def _refused(path: Path, what: str, hint: str, problem: str) -> ConfigError:
    shown = str(path) if len(str(path)) <= 200 else str(path)[:200] + "..."
    return ConfigError.single(f"{what} '{shown}' {problem}", hint=hint)


#: what a JSON5 scan steps over: strings (either quote), comments, and anything but brackets
_JSON_TOKENS = re.compile(r'"(?:[^"\\\n]|\\.)*"|\'(?:[^\'\\\n]|\\.)*\'|//[^\n]*|/\*.*?\*/'
                          r'|[\[{]|[\]}]|\n', re.DOTALL)


def _json_too_deep(text: str, limit: int) -> int | None:
    """The line where JSON or JSON5 text opens its ``limit + 1``-th level, or None."""
    depth, line = 0, 1
    for token in _JSON_TOKENS.finditer(text):
        kind = token.group()[0]
        if kind == "\n":
            line += 1
        elif kind in "[{":
            depth += 1
            if depth > limit:
                return line
        elif kind in "]}":
            depth -= 1
        else:
            line += token.group().count("\n")
    return None


def _yaml_too_deep(text: str, limit: int) -> int | None:
    """The line where YAML text opens its ``limit + 1``-th collection, or None (PyYAML's
    parser is a state machine: its events come without recursion)."""
    depth = 0
    try:
        for event in yaml.parse(text, Loader=yaml.SafeLoader):
            if isinstance(event, yaml.CollectionStartEvent):
                depth += 1
                if depth > limit:
                    return event.start_mark.line + 1
            elif isinstance(event, yaml.CollectionEndEvent):
                depth -= 1
    except yaml.YAMLError:
        pass
    return None


class _Refused(Exception):
    """What an expat handler raises to stop the scan."""


def _xml_problem(text: str, limit: int) -> tuple[int, bool] | None:
    """(line, False) where XML text opens its ``limit + 1``-th element, (line, True) where it
    declares a document type, or None. expat calls the handlers as it reads: no tree is
    built and nothing recurses; a declaration stops it before its entities are read."""
    scan = xml.parsers.expat.ParserCreate()
    depth = 0

    def start(*_) -> None:
        nonlocal depth
        depth += 1
        if depth > limit:
            raise _Refused(scan.CurrentLineNumber, False)

    def end(*_) -> None:
        nonlocal depth
        depth -= 1

    def doctype(*_) -> None:
        raise _Refused(scan.CurrentLineNumber, True)

    scan.StartElementHandler, scan.EndElementHandler = start, end
    scan.StartDoctypeDeclHandler = doctype
    try:
        scan.Parse(text, True)
    except _Refused as refused:
        return refused.args
    except xml.parsers.expat.ExpatError:
        pass
    return None
