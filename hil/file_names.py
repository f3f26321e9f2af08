"""A name of hil's (a bus', a robot's) as the name of a file hil writes: the CAN log of each
bus in a folder of them (``arm.blf``: what :meth:`hil.testing.DrivesBench.log_to` writes and
``hil replay`` reads, each file's frames on the bus of its name), a robot's viewer URDF
(``ur3.urdf``, beside a ``hil_stack`` test's recording).

A name is any text of the bus config or the description, but a file's name is at most
NAME_MAX (255) bytes on Linux: a longer one failed with ENAMETOOLONG when the ``hil_drives``
fixture opened its log and when ``hil_stack`` wrote its URDF. Such a name is cut, and a hash
of the whole name keeps two long names that begin alike apart (hil's choice, as a
content-addressed store names a file); ``hil replay`` maps a log back to its bus through
this same function.
"""

from __future__ import annotations

import hashlib

#: the longest name of one path component Linux takes (NAME_MAX, bytes)
NAME_MAX = 255
#: room left for the file's suffix (".blf", ".urdf", ...)
_SUFFIX_ROOM = 16
#: hex digits of the name's SHA-256 in a cut name: 48 bits, no clash among a config's names
_HASH_DIGITS = 12


def file_stem(name: str) -> str:
    """The name of a file, less its suffix, named after ``name``: the name, or where it is
    too long for a file's name, its start and ``-`` and a hash of it."""
    room = NAME_MAX - _SUFFIX_ROOM
    encoded = name.encode()
    if len(encoded) <= room:
        return name
    digest = hashlib.sha256(encoded).hexdigest()[:_HASH_DIGITS]
    start = encoded[:room - _HASH_DIGITS - 1].decode(errors="ignore")   # whole characters
    return f"{start}-{digest}"
