"""What a PDO's communication (0x1400.., 0x1800..) and mapping (0x1600.., 0x1A00..)
parameters may hold (CiA 301 7.5.2.35-38), checked wherever a value comes from: an SDO write
(:mod:`.node`, which adds the order a remapping takes), a vendor file's own values and a
parameter file restored (:func:`configuration_problems`, which ``hil check`` runs too).

* COB-ID: an 11-bit CAN-ID has bits 11-28 clear (0x06090030); a valid PDO's CAN-ID is none
  of those CiA 301 7.3.5 restricts (0x000-0x07F, 0x101-0x180, 0x581-0x5FF, 0x601-0x67F,
  0x6E0-0x6FF, 0x701-0x7FF: NMT, SDO, heartbeat and reserved; CANopenNode's
  CO_IS_RESTRICTED_CAN_ID, which CO_PDO.c refuses with ODR_INVALID_VALUE) nor the SYNC's
  this drive consumes (0x1005; CiA 301 leaves 0x080 free because SYNC's id is configurable:
  hil's reading, a PDO on it would be taken for the SYNC);
* transmission type: 0-240, 252-255 (252 and 253 TPDOs only);
* mapping: at most the entries the object has and 64 bits, each entry an object a PDO of
  its direction may carry, with the object's own length (or a dummy entry in an RPDO).
"""

from __future__ import annotations

import canopen
from canopen.sdo import SdoAbortedError
from canopen.sdo.constants import (
    ABORT_INVALID_VALUE, ABORT_NO_SUBINDEX, ABORT_NOT_IN_OD, ABORT_PARAMETER_INCOMPATIBLE,
    ABORT_PDO_CANNOT_MAP, ABORT_PDO_LENGTH_EXCEEDED, ABORT_VALUE_TOO_HIGH,
)

#: COB-ID bits (CiA 301): 31 PDO not valid, 29 29-bit frame
NOT_VALID, EXTENDED_FRAME = 0x80000000, 0x20000000
#: transmission types a PDO of this drive may have: synchronous (acyclic 0, every n-th SYNC
#: 1-240), RTR only (252 synchronous, 253 asynchronous; TPDOs only) and event-driven (254,
#: 255); 241-251 are reserved
TRANSMISSION_TYPES = frozenset(range(241)) | {252, 253, 254, 255}
#: bits of the dummy entries (data types 0x0002-0x0007) an RPDO may map
DUMMY_BITS = {0x0002: 8, 0x0003: 16, 0x0004: 32, 0x0005: 8, 0x0006: 16, 0x0007: 32}
#: CiA 301 7.3.5's restricted CAN-IDs (inclusive ranges)
RESTRICTED = ((0x000, 0x07F), (0x101, 0x180), (0x581, 0x5FF), (0x601, 0x67F), (0x6E0, 0x6FF),
              (0x701, 0x7FF))
SYNC_COB_ID = 0x1005
#: the PDOs a drive may have (CiA 301: 512 of each direction)
PDO_COUNT = 512


class PdoParameter:
    """Where an index falls among the PDO parameters, if it does."""

    def __init__(self, index: int):
        self.receive = 0x1400 <= index < 0x1800
        base = index & 0xFE00          # 0x1400, 0x1600, 0x1800, 0x1A00
        self.mapping = base in (0x1600, 0x1A00)
        self.number = index - base
        self.communication_index = (0x1400 if self.receive else 0x1800) + self.number
        self.mapping_index = (0x1600 if self.receive else 0x1A00) + self.number

    @staticmethod
    def of(index: int) -> PdoParameter | None:
        return PdoParameter(index) if 0x1400 <= index < 0x1C00 else None


def cob_id_abort(value: int, sync_id: int) -> int | None:
    """The abort code of a COB-ID a PDO may not have (module doc), None where it may."""
    extended = value & EXTENDED_FRAME
    if not extended and value & 0x1FFFF800:
        return ABORT_INVALID_VALUE               # an 11-bit CAN-ID over 0x7FF
    can_id = value & 0x7FF
    if not value & NOT_VALID and not extended and (
            can_id == sync_id or any(low <= can_id <= high for low, high in RESTRICTED)):
        return ABORT_INVALID_VALUE
    return None


def transmission_abort(value: int, receive: bool) -> int | None:
    if value not in TRANSMISSION_TYPES or receive and value in (252, 253):
        return ABORT_INVALID_VALUE
    return None


def mapped_bits(od: canopen.ObjectDictionary, entry: int, receive: bool) -> int:
    """The length of a mapping entry, after checking it names an object a PDO of this
    direction may carry, with the object's own length (SdoAbortedError otherwise)."""
    index, subindex, bits = entry >> 16, (entry >> 8) & 0xFF, entry & 0xFF
    if index in DUMMY_BITS:          # a dummy entry fills a gap in an RPDO
        if not receive or subindex != 0:
            raise SdoAbortedError(ABORT_PDO_CANNOT_MAP)
        if bits != DUMMY_BITS[index]:
            raise SdoAbortedError(ABORT_PARAMETER_INCOMPATIBLE)
        return bits
    if index not in od:
        raise SdoAbortedError(ABORT_NOT_IN_OD)
    obj = od[index]
    if isinstance(obj, canopen.objectdictionary.ODVariable):
        if subindex != 0:
            raise SdoAbortedError(ABORT_NO_SUBINDEX)
    elif subindex not in obj:
        raise SdoAbortedError(ABORT_NO_SUBINDEX)
    else:
        obj = obj[subindex]
    if not obj.pdo_mappable or not (obj.writable if receive else obj.readable):
        raise SdoAbortedError(ABORT_PDO_CANNOT_MAP)
    if bits != len(obj):
        raise SdoAbortedError(ABORT_PARAMETER_INCOMPATIBLE)
    return bits


def mapping_abort(node, parameter: PdoParameter, count: int) -> int | None:
    """The abort code of a mapping count ``count`` over the entries the node holds now."""
    od = node.object_dictionary
    mapping = parameter.mapping_index
    entries = [sub for sub in od[mapping].subindices if sub > 0]
    if count > len(entries) or any(sub not in entries for sub in range(1, count + 1)):
        return ABORT_VALUE_TOO_HIGH
    try:
        bits = sum(mapped_bits(od, node.value(mapping, sub), parameter.receive)
                   for sub in range(1, count + 1) if node.value(mapping, sub))
    except SdoAbortedError as exc:
        return exc.code
    return ABORT_PDO_LENGTH_EXCEEDED if bits > 64 else None


def configuration_problems(node) -> list[str]:
    """What in the node's PDO parameters as they stand (a vendor file's defaults, a parameter
    file restored) a PDO may not have: '0x1600: ...' each, empty where all is well."""
    od, found = node.object_dictionary, []
    sync_id = node.value(SYNC_COB_ID) & 0x7FF if SYNC_COB_ID in od else 0x080
    for base in (0x1400, 0x1800):
        for number in range(PDO_COUNT):
            parameter = PdoParameter(base + number)
            communication, mapping = parameter.communication_index, parameter.mapping_index
            if communication in od and 1 in _subs(od[communication]):
                code = cob_id_abort(node.value(communication, 1), sync_id)
                if code is not None:
                    found.append(f"0x{communication:04X}:01 COB-ID "
                                 f"0x{node.value(communication, 1):08X} (abort 0x{code:08X})")
            if communication in od and 2 in _subs(od[communication]):
                kind = node.value(communication, 2)
                if transmission_abort(kind, parameter.receive) is not None:
                    found.append(f"0x{communication:04X}:02 transmission type {kind}")
            if mapping in od and 0 in _subs(od[mapping]):
                code = mapping_abort(node, parameter, node.value(mapping, 0))
                if code is not None:
                    found.append(f"0x{mapping:04X} maps {node.value(mapping, 0)} entries "
                                 f"(abort 0x{code:08X})")
    return found


def _subs(obj) -> set[int]:
    return {0} if isinstance(obj, canopen.objectdictionary.ODVariable) else set(obj.subindices)
