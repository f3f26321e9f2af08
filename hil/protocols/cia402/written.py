"""What a value written into a CiA 402 drive's object dictionary must be, whatever the order
of the writes (the order a remapping takes is the node's: :mod:`.node`), and an object
dictionary holding values without a node (:class:`StoredDictionary`: what ``hil check``
restores a parameter file into, :mod:`.start_check`). Both sides of the bus read this
module; it runs no drive.

* every value as :mod:`.ranges` checks it (its length, its range);
* a PDO's COB-ID, transmission type and mapping entries (:mod:`.pdo_parameters`);
* 0x1016 heartbeat consumer: one entry per producer node (CiA 301 7.5.2.33: 0x06040043);
* 0x1019 synchronous counter overflow: 0 or 2-240 (CiA 301 7.5.2.22).
"""

from __future__ import annotations

import canopen
from canopen.objectdictionary import NUMBER_TYPES, ODVariable
from canopen.sdo import SdoAbortedError
from canopen.sdo.constants import (ABORT_INVALID_VALUE, ABORT_NO_SUBINDEX, ABORT_NOT_IN_OD,
                                   ABORT_PARAMETER_INCOMPATIBLE)

from hil.protocols.cia402.pdo_parameters import (SYNC_COB_ID, PdoParameter, cob_id_abort,
                                                 mapped_bits, transmission_abort)
from hil.protocols.cia402.ranges import range_abort

CONSUMER_HEARTBEAT = 0x1016
SYNC_OVERFLOW = 0x1019


def write_abort(values, index: int, subindex: int, od: ODVariable, data: bytes) -> int | None:
    """The abort code of ``data`` written to (index, subindex) of ``values`` (a node, or a
    :class:`StoredDictionary`), None where the object takes it (module doc)."""
    code = range_abort(od, data)
    if code is not None or od.data_type not in NUMBER_TYPES:
        return code
    value = od.decode_raw(data)
    parameter = PdoParameter.of(index)
    if parameter is not None and parameter.mapping:
        if subindex > 0 and value:
            try:
                mapped_bits(values.object_dictionary, value, parameter.receive)
            except SdoAbortedError as exc:
                return exc.code
    elif parameter is not None and subindex == 1:
        return cob_id_abort(value, sync_id(values))
    elif parameter is not None and subindex == 2:
        return transmission_abort(value, parameter.receive)
    elif index == CONSUMER_HEARTBEAT and subindex > 0:
        return _consumer_abort(values, subindex, value)
    elif index == SYNC_OVERFLOW and value in (1, *range(241, 256)):
        return ABORT_INVALID_VALUE
    return None


def sync_id(values) -> int:
    """The CAN-ID of the SYNC the drive consumes (0x1005, else CiA 301's 0x080)."""
    return (values.value(SYNC_COB_ID) & 0x7FF if SYNC_COB_ID in values.object_dictionary
            else 0x080)


def _consumer_abort(values, subindex: int, value: int) -> int | None:
    producer, period = (value >> 16) & 0xFF, value & 0xFFFF
    if not producer or not period:
        return None
    for sub in values.object_dictionary[CONSUMER_HEARTBEAT].subindices:
        other = values.value(CONSUMER_HEARTBEAT, sub) if sub not in (0, subindex) else 0
        if (other >> 16) & 0xFF == producer and other & 0xFFFF:
            return ABORT_PARAMETER_INCOMPATIBLE                  # one entry per node
    return None


class StoredDictionary:
    """An object dictionary and the values written into it, as a drive's node keeps them
    (``data_store``), with the node's checks of a write and nothing else: no callbacks,
    no drive."""

    def __init__(self, od: canopen.ObjectDictionary, node_id: int):
        self.object_dictionary, self.id = od, node_id
        self.data_store: dict[int, dict[int, bytes]] = {}

    def value(self, index: int, subindex: int = 0) -> int:
        """As :meth:`.node.DriveNode.value` reads it: the value stored, else the file's,
        else 0."""
        try:
            entry = self._find_object(index, subindex)
        except SdoAbortedError:
            return 0
        data = self.data_store.get(index, {}).get(subindex)
        if data is not None:
            return entry.decode_raw(data)
        given = entry.value if entry.value is not None else entry.default
        return given if isinstance(given, int) else 0

    def _find_object(self, index: int, subindex: int) -> ODVariable:
        """canopen's LocalNode's lookup, its aborts."""
        obj = self.object_dictionary.get(index)
        if obj is None:
            raise SdoAbortedError(ABORT_NOT_IN_OD)
        if isinstance(obj, ODVariable):
            return obj
        if subindex not in obj.subindices:
            raise SdoAbortedError(ABORT_NO_SUBINDEX)
        return obj[subindex]

    def _check_write(self, index: int, subindex: int, od: ODVariable, data: bytes) -> None:
        code = write_abort(self, index, subindex, od, data)
        if code is not None:
            raise SdoAbortedError(code)

    def set_data(self, index: int, subindex: int, data: bytes) -> None:
        self._check_write(index, subindex, self._find_object(index, subindex), data)
        self.data_store.setdefault(index, {})[subindex] = data
