"""Reading an EDS, DCF (CiA 306: INI text) or EPF (XML) file into canopen's object
dictionary: bounded, decoded, parsed without a traceback, or a ValueError naming the file.

CiA 306 says an EDS is ASCII; vendors' tools write them in their Windows code page
(cp1252, of which Latin-1 is the printable part) or UTF-8, so a file is read as UTF-8 and,
where it is not, as cp1252; a byte neither decodes is named with its line. The bounds are
hil's choices (CiA 306 gives none): a vendor's EDS is some hundred kB with a few hundred to
two thousand sections; a million sections took ``hil check`` 52 s and 2.8 GB (measured
2026-12-06). An EPF is XML: its document type declaration (entities that expand without
bound) and a nesting deeper than :data:`hil.input_files.MAX_NESTING` are refused before
ElementTree parses it (:func:`hil.input_files.check_nesting`).
"""

from __future__ import annotations

import configparser
import io
import re
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import canopen
from canopen.objectdictionary import ObjectDictionaryError
from canopen.objectdictionary.eds import import_eds
from canopen.objectdictionary.epf import import_epf

from hil.errors import HilError
from hil.input_files import check_nesting, read_input_bytes

#: the largest EDS/DCF/EPF hil reads (bytes)
MAX_EDS_BYTES = 4 * 1024 * 1024
#: the most sections ([1018], [1018sub1] ...) or EPF parameters it reads
MAX_SECTIONS = 8192
SUFFIXES = (".eds", ".dcf", ".epf")
_SECTION = re.compile(rb"^[ \t]*\[", re.MULTILINE)
_HINT = "give the drive vendor's EDS or DCF, relative to the bus config"


def read_text(path: Path) -> str:
    """The file's text, bounded and decoded (module doc); ValueError naming it."""
    if path.suffix.lower() not in SUFFIXES:
        raise ValueError(f"eds: {path.name} is no EDS, DCF or EPF (its name ends in "
                         f"'{path.suffix}', not .eds, .dcf or .epf)")
    try:
        data = read_input_bytes(path, "EDS", _HINT, MAX_EDS_BYTES)
    except HilError as exc:
        raise ValueError(f"eds: {exc.diagnostics[0].message}") from None
    marks = len(_SECTION.findall(data)) if path.suffix.lower() != ".epf" \
        else data.count(b"<Parameter ")
    if marks > MAX_SECTIONS:
        raise ValueError(f"eds: {path} has {marks} sections, over the {MAX_SECTIONS} hil "
                         f"reads (a drive's EDS has a few hundred)")
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError:
        pass
    try:
        return data.decode("cp1252")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        raise ValueError(f"eds: {path} line {line}: byte 0x{data[exc.start]:02X} is neither "
                         f"UTF-8 nor Windows-1252 text (CiA 306: an EDS is ASCII)") from None


def parse(path: Path, text: str, node_id: int) -> canopen.ObjectDictionary:
    """canopen's object dictionary of the file's ``text`` (from :func:`read_text`), its
    $NODEID values for ``node_id``; ValueError naming the file and line where it is none."""
    epf = path.suffix.lower() == ".epf"
    if epf:
        try:
            check_nesting(text, "xml", path, "EPF")
        except HilError as exc:
            found = exc.diagnostics[0]
            raise ValueError(f"eds: {path} line {found.line}: {found.message}") from None
    try:
        return import_epf(ElementTree.fromstring(text)) if epf else \
            import_eds(io.StringIO(text), node_id)
    except (configparser.Error, ValueError, KeyError, TypeError, AttributeError, IndexError,
            ObjectDictionaryError, ElementTree.ParseError) as exc:
        # the error's kind and line, never the file's text (it may be any file)
        line = getattr(exc, "lineno", None) or getattr(exc, "position", (None,))[0]
        where = f" at line {line}" if line else ""
        raise ValueError(f"eds: {path} is not a readable EDS/DCF/EPF ({type(exc).__name__}"
                         f"{where})") from None
