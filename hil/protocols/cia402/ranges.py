"""What a CANopen drive of hil takes into an object: the value ranges every write is checked
against before it reaches the drive, whichever way it comes (SDO expedited, segmented or
block; a parameter file restored; a vendor file's own values)."""

from __future__ import annotations

import math

from canopen.objectdictionary import NUMBER_TYPES
from canopen.sdo import SdoAbortedError
from canopen.sdo.constants import ABORT_INVALID_VALUE, ABORT_VALUE_TOO_HIGH, ABORT_VALUE_TOO_LOW

#: objects whose 0 would leave a move without its ramp: a quick stop or the watchdog's stop
#: that never decelerates (0x6085), a halt or a profile move's end that never comes (0x6084),
#: a move that never starts (0x6083), the drive's own acceleration and deceleration bounds
#: (0x60C5, 0x60C6). CiA 402 gives them as rates and no meaning to 0; hil refuses 0 with
#: 0x06090032 whatever a vendor's file declares (hil's reading: a stop must decelerate; a
#: master that wants the steepest stop writes the largest rate)
RATES = frozenset({0x6083, 0x6084, 0x6085, 0x60C5, 0x60C6})


#: CiA 301 "data type does not match, length of service parameter does not match"
ABORT_LENGTH = 0x06070010


def range_abort(od, data: bytes) -> int | None:
    """The CiA 301 abort code of a value an object does not take, None where it takes it:
    bytes of another length than a number's (0x06070010, where canopen's decoder raises),
    :func:`outside` its range (0x06090030/31/32), or a rate of :data:`RATES` of 0."""
    if od.data_type not in NUMBER_TYPES:
        return None
    if len(data) != len(od) // 8:
        return ABORT_LENGTH
    value = od.decode_raw(data)
    code = outside(od, value)
    if code is None and od.index in RATES and value <= 0:
        return ABORT_VALUE_TOO_LOW
    return code


def outside(od, value) -> int | None:
    """The abort code of a number outside an object's range, None inside: its LowLimit and
    HighLimit (canopen's encoder only logs them), else its data type's (a decoded integer is
    in it); a REAL32/REAL64 must be a number (NaN: 0x06090030) and finite (inf is past any
    range: hil's reading, CiA 301 has no code of its own for it)."""
    if value != value:                                   # NaN
        return ABORT_INVALID_VALUE
    if value == -math.inf or od.min is not None and value < od.min:
        return ABORT_VALUE_TOO_LOW
    if value == math.inf or od.max is not None and value > od.max:
        return ABORT_VALUE_TOO_HIGH
    return None


def check_range(od, data: bytes) -> None:
    """Raise the SDO abort of :func:`range_abort`, if any."""
    code = range_abort(od, data)
    if code is not None:
        raise SdoAbortedError(code)
