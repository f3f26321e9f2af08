"""Store and restore parameters (CiA 301 0x1010, 0x1011) of hil's CANopen drives.

Writing "save" (0x65766173) to 0x1010 sub-index 1 (all), 2 (communication, 0x1000-0x1FFF),
3 (application, 0x6000-0x9FFF) or 4 (manufacturer, 0x2000-0x5FFF) keeps the area's
parameters as the drive's power-on values: a reset node (and a restart of the drive) comes
back with them, a reset communication with the communication area's. Writing "load"
(0x64616F6C) to 0x1011's sub-index of an area forgets what was saved there: the next reset
comes back with the defaults. Any other value: abort 0x08000020. Both read 1 ("saves on
command"). A parameter is an object that is writable and not PDO-mappable (a controlword,
target or mode saved and restored at boot would move a motor that nobody commanded: hil's
reading where CiA 301 says "parameters"). With a file (``options: {parameter_file: F}``)
what is saved lasts across ``hil sim`` restarts: JSON of ``"index:sub": "hex bytes"``
(:mod:`.parameter_file`), checked as a restore checks it where ``hil check`` runs
(:func:`.start_check.start_problem`).
"""

from __future__ import annotations

import json
from pathlib import Path

import canopen
from canopen.sdo import SdoAbortedError

from hil.protocols.cia402.parameter_file import read_saved
from hil.protocols.cia402.pdo_parameters import configuration_problems
from hil.protocols.cia402.written import write_abort


SAVE, LOAD = 0x65766173, 0x64616F6C
ABORT_CANNOT_STORE = 0x08000020
#: 0x1010/0x1011 sub-index -> the index ranges it covers
AREAS = {1: ((0x1000, 0xA000),), 2: ((0x1000, 0x2000),), 3: ((0x6000, 0xA000),),
         4: ((0x2000, 0x6000),)}
COMMUNICATION = AREAS[2][0]
#: never saved: the store commands themselves and the error history
NOT_SAVED = frozenset({0x1003, 0x1010, 0x1011})


class ParameterStore:
    """What a drive saved, by (index, sub-index), and the file that keeps it (if any)."""

    def __init__(self, file: Path | None = None):
        self.file = file
        self.saved: dict[tuple[int, int], bytes] = read_saved(file) if file else {}

    def command(self, index: int, subindex: int, value: int, node: canopen.LocalNode) -> None:
        """A write to 0x1010 or 0x1011 (raises the CiA 301 abort where it cannot be done)."""
        areas = AREAS.get(subindex)
        if areas is None or value != (SAVE if index == 0x1010 else LOAD):
            raise SdoAbortedError(ABORT_CANNOT_STORE)
        for key in [k for k in self.saved if _within(k[0], areas)]:
            del self.saved[key]
        if index == 0x1010:
            self.saved.update({(i, s): bytes(data) for i, subs in node.data_store.items()
                               for s, data in subs.items()
                               if _within(i, areas) and _parameter(node, i, s)})
        self._write()

    def restore(self, node, communication_only: bool) -> list[str]:
        """Put the saved values back into ``node`` (a drive's, or a
        :class:`.written.StoredDictionary`) after a reset put the defaults: the communication
        area's as stored, the others through the node's write checks and callbacks. A value
        the drive does not take is not restored (returned: '0x1017:00: why', each):
        each as a write checks it (:mod:`.ranges`, the length; a PDO's parameters as they
        stand together, :func:`.pdo_parameters.configuration_problems`, the communication
        area left as it was where they do not)."""
        if not self.saved:
            return []
        refused = []
        before = {index: dict(subs) for index, subs in node.data_store.items()
                  if _within(index, (COMMUNICATION,))}
        for (index, subindex), data in sorted(self.saved.items()):
            communication = _within(index, (COMMUNICATION,))
            try:
                if communication:
                    # as stored (a PDO's parameters in the order a write would refuse), but
                    # only a value the object takes, as a write checks it
                    code = write_abort(node, index, subindex,
                                       node._find_object(index, subindex), data)
                    if code is not None:
                        raise SdoAbortedError(code)
                    node.data_store.setdefault(index, {})[subindex] = data
                elif not communication_only:
                    node.set_data(index, subindex, data)
            except (SdoAbortedError, KeyError) as exc:
                refused.append(f"0x{index:04X}:{subindex:02X}: {_why(exc)}")
        pdo = configuration_problems(node)
        if pdo:
            refused.extend(pdo)
            for index in [i for i in node.data_store if _within(i, (COMMUNICATION,))]:
                del node.data_store[index]
            node.data_store.update(before)
        return refused

    def _write(self) -> None:
        if self.file is None:
            return
        try:
            self.file.write_text(json.dumps(
                {f"{i:04X}:{s:02X}": data.hex() for (i, s), data in sorted(self.saved.items())},
                indent=1))
        except OSError as exc:
            raise SdoAbortedError(ABORT_CANNOT_STORE) from exc


def _why(exc: Exception) -> str:
    if isinstance(exc, SdoAbortedError):
        return f"abort 0x{exc.code:08X}"
    return "no such object in the drive's object dictionary"


def _within(index: int, areas) -> bool:
    return index not in NOT_SAVED and any(low <= index < high for low, high in areas)


def _parameter(node: canopen.LocalNode, index: int, subindex: int) -> bool:
    entry = node.object_dictionary.get(index)
    if entry is not None and not isinstance(entry, canopen.objectdictionary.ODVariable):
        entry = entry.subindices.get(subindex)
    return entry is not None and entry.writable and not entry.pdo_mappable
