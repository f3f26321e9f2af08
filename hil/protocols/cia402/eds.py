"""A vendor's EDS or DCF read as a CiA 402 drive's: checked, and what in it hil gives no
meaning to. No simulated drive here: the bus config parser and ``hil check`` read it (the
drive's side is :mod:`.personality`)."""

from __future__ import annotations

from pathlib import Path

import canopen
from canopen.objectdictionary import NUMBER_TYPES, ODVariable

from hil.protocols.cia402.eds_file import parse, read_text
from hil.protocols.cia402.eds_types import check_types
from hil.protocols.cia402.ranges import outside

#: objects read from the drive's state, not stored in its object dictionary
LIVE_OBJECTS = frozenset({0x6041, 0x6061, 0x6064, 0x606C, 0x6077, 0x60F4, 0x603F, 0x1001})
#: the objects hil gives a meaning to in any personality (:mod:`.objects`, :mod:`.state`,
#: the communication objects of :mod:`.node` and :mod:`.drive`); hil's own manufacturer
#: objects 0x2000 and 0x2010 only in hil's own EDS
MEANINGFUL = frozenset({
    0x1000, 0x1001, 0x1003, 0x1008, 0x1009, 0x100A, 0x1010, 0x1011, 0x1016, 0x1017, 0x1018,
    0x1019, 0x1200,
    *range(0x1400, 0x1404), *range(0x1600, 0x1604), *range(0x1800, 0x1804),
    *range(0x1A00, 0x1A04),
    0x6007, 0x6040, 0x605A, 0x6060, 0x6065, 0x6066, 0x6071, 0x6072, 0x6076, 0x607A,
    0x607C, 0x607D, 0x607F, 0x6080, 0x6081, 0x6083, 0x6084, 0x6085, 0x6087, 0x6088,
    0x608F, 0x6091, 0x6092, 0x6098, 0x6099, 0x609A, 0x60A9, 0x60B1, 0x60B2, 0x60C1, 0x60C2,
    0x60FF, 0x6502,
    *LIVE_OBJECTS})
#: CiA 402 0x1000: device profile number in the low word
PROFILE_402 = 402


def read_dictionary(eds: Path) -> canopen.ObjectDictionary:
    """The object dictionary of an EDS/DCF/EPF (its $NODEID values for node 1), checked to
    be a CiA 402 drive's: read within bounds (:mod:`.eds_file`), every entry of a type hil
    runs with (:mod:`.eds_types`), every value one its object takes, a controlword and a
    statusword, and 0x1000 (where the file gives it) naming profile 402; a ValueError that
    names the file and what is wrong otherwise."""
    return checked_dictionary(eds, read_text(eds), 1)


def checked_dictionary(eds: Path, text: str, node_id: int) -> canopen.ObjectDictionary:
    """:func:`read_dictionary` of the file's text, read already, for ``node_id``."""
    od = parse(eds, text, node_id)
    check_types(eds, od, MEANINGFUL)
    _check_values(eds, od)
    device_type = file_value(od, 0x1000)
    missing = [f"0x{i:04X}" for i in (0x6040, 0x6041) if i not in od]
    if missing or (device_type and device_type & 0xFFFF != PROFILE_402):
        why = (f"it has no {' or '.join(missing)}" if missing
               else f"its device type 0x1000 is 0x{device_type:08X}")
        raise ValueError(f"eds: {eds} is not a CiA 402 drive's EDS ({why})")
    if not isinstance(od.get(0x1017), ODVariable):
        # hil's drives produce a heartbeat (CiA 301 7.2.8.3.2.2; canopen's NMT slave reads
        # 0x1017 entering pre-operational): an EDS without it as a variable (missing, or an
        # ObjectType canopen drops) started a drive that raised KeyError at boot
        raise ValueError(f"eds: {eds} has no variable 0x1017 (Producer heartbeat time): "
                         "hil's drives send a heartbeat; add [1017] with ObjectType=0x7, "
                         "DataType=0x0006 (UNSIGNED16, ms)")
    return od


def objects_without_meaning(od: canopen.ObjectDictionary) -> list[tuple[int, str]]:
    """(index, name) of each object hil stores and reads back but does not act on."""
    return [(index, od[index].name) for index in sorted(od.indices)
            if index >= 0x1000 and index not in MEANINGFUL]     # below: data types


def file_value(od: canopen.ObjectDictionary, index: int) -> int | None:
    """What the file says a variable holds: a DCF's ParameterValue, else its DefaultValue."""
    entry = od.get(index)
    if not isinstance(entry, ODVariable):
        return None
    return entry.value if entry.value is not None else entry.default


def _check_values(eds: Path, od: canopen.ObjectDictionary) -> None:
    """Each number the file gives (a DCF's ParameterValue, else DefaultValue) is one its
    object takes (:func:`.ranges.outside`: the file's own limits, finite): the drive starts
    with these values, as a master's SDO download of them would be checked."""
    for obj in od.values():
        for entry in [obj] if isinstance(obj, ODVariable) else obj.values():
            value = entry.value if entry.value is not None else entry.default
            if entry.data_type not in NUMBER_TYPES or not isinstance(value, (int, float)):
                continue
            if outside(entry, value) is not None:
                where = f"0x{entry.index:04X}" + (f" sub-index {entry.subindex}"
                                                  if not isinstance(obj, ODVariable) else "")
                raise ValueError(f"eds: {eds} gives {where} ({entry.name}) the value {value}, "
                                 f"outside what the object takes (LowLimit {entry.min}, "
                                 f"HighLimit {entry.max}, a finite number): correct the file")
