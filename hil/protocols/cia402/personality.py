"""A vendor's EDS or DCF as a simulated CiA 402 drive's personality.

A drive whose bus config names a file (``options: {eds: FILE}``) takes from it what a
master checks and configures: the identity (0x1000, 0x1018), the object dictionary with
every object's data type, access type, limits and default, the default PDO mapping and
communication parameters, and the operation modes it offers (0x6502). hil goes on giving
the CiA 402 objects their meaning through the plant (:mod:`.objects`); the file's
manufacturer-specific objects (0x2000-0x5FFF) and the standard ones hil has no meaning
for are stored and read back as they were written (:func:`.eds.objects_without_meaning`,
which ``hil check`` lists). Without a file the drive is hil's own
(:func:`hil.resources.eds_path`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import canopen

from hil.protocols.cia402.eds import checked_dictionary, file_value
from hil.protocols.cia402.eds_file import read_text
from hil.protocols.cia402.state import MODE_CODES
from hil.resources import eds_path


@dataclass(frozen=True)
class Personality:
    """Which object dictionary a drive has, and what follows from it."""

    eds: Path
    #: hil's own EDS (its manufacturer objects 0x2000, 0x2010 have hil's meaning)
    own: bool
    #: the operation modes (0x6060 codes) the drive takes: hil's, less those the file's
    #: 0x6502 does not offer
    modes: frozenset[int]
    #: the file's text, read once (bounded) and checked: each node's dictionary is parsed
    #: from it, with the node's own id for $NODEID
    text: str = field(repr=False, compare=False, default="")

    @classmethod
    def of(cls, eds: Path | None) -> Personality:
        """The personality of a file (None: hil's own); a file that is no CiA 402 drive's
        EDS/DCF is a ValueError naming it (:func:`.eds.read_dictionary`)."""
        own = eds is None
        path = eds_path() if own else eds
        text = read_text(path)
        od = checked_dictionary(path, text, 1)
        modes = frozenset(MODE_CODES)
        offered = None if own else file_value(od, 0x6502)
        if offered:       # bit (code - 1) of each mode offered (CiA 402 0x6502)
            modes = frozenset(code for code in MODE_CODES if offered >> (code - 1) & 1)
        return cls(path, own, modes, text)

    def dictionary(self, node_id: int) -> canopen.ObjectDictionary:
        """A fresh object dictionary of the file for the node ``node_id`` (checked at
        :meth:`of`; the $NODEID values are the node's)."""
        return checked_dictionary(self.eds, self.text, node_id)
