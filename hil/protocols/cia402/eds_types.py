"""The data types in a vendor's EDS/DCF/EPF that hil can run with: checked where ``hil check``
runs, so that the drive ``hil sim`` starts never meets an object of another type.

* every entry has a data type canopen encodes (CiA 301 7.1: the basic types; a type hil does
  not model, TIME_OF_DAY, TIME_DIFFERENCE, or a type the file names but does not define, is
  refused), and a value (DefaultValue, a DCF's ParameterValue) that encodes in it;
* every object hil gives a meaning to (:data:`.eds.MEANINGFUL`) has the kind (a variable, an
  array or a record) and the data types CiA 301 and CiA 402 give it (an integer may be of
  the other signedness or wider, as vendors' files have them): those of hil's own EDS
  (built from their tables by tools/make_cia402_eds.py), and for the two it lacks, CiA 301's
  0x1200 (SDO server parameter) and CiA 402's 0x60A9 (SI unit velocity). A sub-index hil's
  EDS does not have is free, but a PDO mapping's and the error history's are UNSIGNED32.
"""

from __future__ import annotations

import functools
import struct
from pathlib import Path

import canopen
from canopen.objectdictionary import ODVariable, datatypes

from hil.protocols.cia402.eds_file import parse, read_text
from hil.resources import eds_path

U8, U32 = datatypes.UNSIGNED8, datatypes.UNSIGNED32
#: what hil's own EDS lacks: index -> {sub-index: data type} (sub-index None: a variable)
_OTHERS = {0x1200: {0: U8, 1: U32, 2: U32}, 0x60A9: {None: U32}}
#: data types whose entries hold bytes, text: the others are numbers (ODVariable.STRUCT_TYPES)
_BYTES = (datatypes.OCTET_STRING, datatypes.DOMAIN)
_TEXT = (datatypes.VISIBLE_STRING, datatypes.UNICODE_STRING)
_NAMES = {getattr(datatypes, name): name for name in dir(datatypes)
          if name.isupper() and isinstance(getattr(datatypes, name), int)}


def check_types(eds: Path, od: canopen.ObjectDictionary, meaningful: frozenset[int]) -> None:
    """ValueError naming the file, the object and what is wrong (module doc)."""
    expected = _expected()
    for obj in od.values():
        entries = [obj] if isinstance(obj, ODVariable) else list(obj.values())
        for entry in entries:
            _check_encodes(eds, obj, entry)
        if obj.index not in meaningful:
            continue
        wanted = _OTHERS.get(obj.index) or expected.get(obj.index)
        if wanted is None:
            continue
        variable = None in wanted
        if variable != isinstance(obj, ODVariable):
            raise ValueError(f"eds: {eds} gives 0x{obj.index:04X} ({obj.name}) as "
                             f"{'a variable' if not variable else 'an array/record'}; "
                             f"CiA 301/402 define it as "
                             f"{'a variable' if variable else 'an array or record'}")
        for entry in entries:
            sub = None if variable else entry.subindex
            want = wanted.get(sub, U32 if _listed(obj.index) else entry.data_type)
            if not _holds(entry, want):
                raise ValueError(f"eds: {eds} gives {_where(obj, entry)} ({entry.name}) the "
                                 f"data type {_name(entry.data_type)}; CiA 301/402 define it "
                                 f"as {_name(want)}: correct the file")


@functools.cache
def _expected() -> dict[int, dict[int | None, int]]:
    """index -> {sub-index (None: a variable): data type}, from hil's own EDS."""
    own = eds_path()
    od = parse(own, read_text(own), 1)
    return {obj.index: ({None: obj.data_type} if isinstance(obj, ODVariable) else
                        {entry.subindex: entry.data_type for entry in obj.values()})
            for obj in od.values()}


def _holds(entry: ODVariable, want: int) -> bool:
    """Whether an entry of the file's type holds what CiA gives the object: the same type,
    or an integer of the other signedness or wider (vendors differ there: Yiyou's EU
    servo gives 0x6072 as INTEGER16, CiA 402 UNSIGNED16; hil's values for it fit either)."""
    kind = entry.data_type
    if kind == want:
        return True
    integers = datatypes.INTEGER_TYPES
    return kind in integers and want in integers and len(entry) >= _bits(want)


def _bits(kind: int) -> int:
    return ODVariable.STRUCT_TYPES[kind].size * 8


def _listed(index: int) -> bool:
    """A PDO mapping or the error history: every entry an UNSIGNED32 (CiA 301)."""
    return index == 0x1003 or 0x1600 <= index < 0x1800 or 0x1A00 <= index < 0x1C00


def _check_encodes(eds: Path, obj, entry: ODVariable) -> None:
    kind = entry.data_type
    known = kind in ODVariable.STRUCT_TYPES or kind in _BYTES or kind in _TEXT
    value = entry.value if entry.value is not None else entry.default
    if known and value is not None:
        fits = isinstance(value, bytes) if kind in _BYTES else isinstance(value, str) \
            if kind in _TEXT else isinstance(value, (int, float)) and not isinstance(value, bool)
        try:
            known = fits and entry.encode_raw(value) is not None
        except (struct.error, ValueError, TypeError, OverflowError, UnicodeError):
            known = False
        if not known:
            raise ValueError(f"eds: {eds} gives {_where(obj, entry)} ({entry.name}) the "
                             f"value {str(value)[:40]!r}, which is no {_name(kind)}: correct "
                             f"the file")
    if not known:
        raise ValueError(f"eds: {eds} gives {_where(obj, entry)} ({entry.name}) the data type "
                         f"{_name(kind)}, which hil does not model (CiA 301's basic types: "
                         f"BOOLEAN, INTEGERn, UNSIGNEDn, REAL32/64, strings, DOMAIN)")


def _where(obj, entry: ODVariable) -> str:
    return f"0x{entry.index:04X}" + ("" if isinstance(obj, ODVariable)
                                     else f" sub-index {entry.subindex}")


def _name(kind) -> str:
    return _NAMES.get(kind, f"0x{kind:04X}" if isinstance(kind, int) else "none")
