"""The file a drive's saved parameters last in across ``hil sim`` restarts (``options:
{parameter_file: F}``, :mod:`.storage`): JSON of ``"index:sub": "hex bytes"``, as hil writes
it, read within bounds or refused with a HilError naming the file.

The bounds are hil's (CiA 301 stores parameters in the device, in no file format): the
file is read as every input hil reads (:func:`hil.input_files.read_input_file`: a regular
file, no FIFO or device, nested no deeper than JSON's 100 levels) of at most
:data:`MAX_BYTES`, and holds at most :data:`MAX_ENTRIES` values: a drive's object dictionary
has some hundred parameters; a million keys took 24 s to start (measured 2026-12-06).
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

from hil.errors import HilError
from hil.input_files import read_input_file

MAX_BYTES = 1024 * 1024
MAX_ENTRIES = 4096
_KEY = re.compile(r"[0-9A-Fa-f]{4}:[0-9A-Fa-f]{2}")
_HEX = re.compile(r"(?:[0-9A-Fa-f]{2})*")
#: the longest value a saved parameter holds (bytes): a string or domain hil stores
MAX_VALUE_BYTES = 4096
_HINT = "remove it (the drive then starts from its defaults) or save the parameters again"


def read_saved(path: Path) -> dict[tuple[int, int], bytes]:
    """(index, sub-index) -> bytes, from ``path`` ({} where there is no file yet)."""
    try:
        os.lstat(path)
    except FileNotFoundError:
        return {}
    except OSError:
        pass                 # a name too long, ...: the reader says what, naming the file
    text = read_input_file(path, "parameter file", _HINT, MAX_BYTES, syntax="json")
    try:
        raw = json.loads(text)
    except ValueError as exc:
        raise _refused(path, f"it is not JSON ({exc})") from None
    if not isinstance(raw, dict):
        raise _refused(path, "it is not a JSON object of \"index:sub\": \"hex bytes\"")
    if len(raw) > MAX_ENTRIES:
        raise _refused(path, f"it holds {len(raw)} values, over the {MAX_ENTRIES} hil reads")
    saved = {}
    for key, value in raw.items():
        if not _KEY.fullmatch(key):
            raise _refused(path, f"the key {key[:40]!r} is no \"index:sub\" in hex (\"6081:00\")")
        if not isinstance(value, str) or not _HEX.fullmatch(value) \
                or len(value) > 2 * MAX_VALUE_BYTES:
            raise _refused(path, f"\"{key}\" holds {str(value)[:40]!r}, not the hex of at most "
                                 f"{MAX_VALUE_BYTES} bytes")
        index, subindex = key.split(":")
        saved[int(index, 16), int(subindex, 16)] = bytes.fromhex(value)
    return saved


def _refused(path: Path, why: str) -> HilError:
    return HilError.single(f"{path}: not a parameter file hil wrote: {why}", hint=_HINT)
