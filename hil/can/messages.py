"""``can.Message`` objects built slot by slot, for the per-frame paths.

``can.Message(...)`` spends much of its time on keyword handling (0.58 us here); a control
cycle of the ur3 builds 40 messages (each frame, then each receiver's copy), so the
builders here fill the slots directly and do in 0.31-0.34 us what the constructor does for
the same arguments. ``tests/test_virtual_bus.py`` pins them against the constructor,
field by field, so a slot python-can adds cannot be left unset.
"""

from __future__ import annotations

import can

_new_message = can.Message.__new__

#: marks an extended (29-bit) id in an id used as a key, as SocketCAN's ``CAN_EFF_FLAG``
#: does in its ``can_id``: a drive that listens on extended ids below 0x800 (a CubeMars
#: servo command, ``mode << 8 | id``) must not hear the standard frame of the same number
EXTENDED = 0x80000000
#: the bits of an arbitration id
ID_BITS = 0x1FFFFFFF

#: a data frame by its parts: its dispatch key (:func:`frame_key`) and its data
FrameParts = tuple[int, bytes | bytearray]


def frame_key(msg: can.Message) -> int:
    """The id frames are dispatched by: the arbitration id, with :data:`EXTENDED` set for an
    extended frame whose id a standard frame could carry (above 0x7FF the id says it)."""
    if msg.is_extended_id and msg.arbitration_id <= 0x7FF:
        return msg.arbitration_id | EXTENDED
    return msg.arbitration_id


def identifier(key: int) -> tuple[int, bool]:
    """The arbitration id of the frame of dispatch key ``key`` and whether it is extended
    (the inverse of :func:`frame_key`; flag bits above the id, such as a wire's, ignored)."""
    arbitration_id = key & ID_BITS
    return arbitration_id, bool(key & EXTENDED) or arbitration_id > 0x7FF


def extended(can_id: int) -> int:
    """The dispatch key of the extended frame of id ``can_id``."""
    return can_id | EXTENDED if can_id <= 0x7FF else can_id


def sent_key(can_id: int) -> int:
    """The dispatch key (:func:`frame_key`) of the frame :func:`data_frame` builds for
    ``can_id``."""
    if can_id <= 0x7FF:
        return can_id
    return extended(can_id & ID_BITS)


def data_frame(arbitration_id: int, data: bytes | bytearray, remote: bool = False
               ) -> can.Message:
    """What ``can.Message(arbitration_id=..., data=..., is_extended_id=arbitration_id >
    0x7FF, is_remote_frame=remote)`` builds: canopen's frames; an id that carries
    :data:`EXTENDED` is sent as that extended id."""
    if remote:
        data = bytearray()
    elif not isinstance(data, bytearray):
        data = bytearray(data)
    is_extended = arbitration_id > 0x7FF
    arbitration_id &= ID_BITS
    return _filled(_new_message(can.Message), 0.0, arbitration_id, is_extended,
                   remote, False, None, len(data), data, False, True, False, False)


def received_copy(msg: can.Message, timestamp: float, channel, is_rx: bool) -> can.Message:
    """A receiver's own copy of ``msg`` (its own data), stamped ``timestamp`` on
    ``channel``."""
    return _filled(_new_message(can.Message), timestamp, msg.arbitration_id,
                   msg.is_extended_id, msg.is_remote_frame, msg.is_error_frame, channel,
                   msg.dlc, bytearray(msg.data), msg.is_fd, is_rx, msg.bitrate_switch,
                   msg.error_state_indicator)


def received_frame(timestamp: float, arbitration_id: int, is_extended_id: bool,
                   is_remote_frame: bool, is_error_frame: bool, dlc: int, data: bytes,
                   channel) -> can.Message:
    """What ``can.Message(timestamp=..., arbitration_id=..., ..., is_rx=True)`` builds for a
    frame received from a wire (its data copied into a bytearray)."""
    return _filled(_new_message(can.Message), timestamp, arbitration_id, is_extended_id,
                   is_remote_frame, is_error_frame, channel, dlc, bytearray(data), False, True,
                   False, False)


def _filled(msg: can.Message, timestamp, arbitration_id, is_extended_id, is_remote_frame,
            is_error_frame, channel, dlc, data, is_fd, is_rx, bitrate_switch,
            error_state_indicator) -> can.Message:
    msg.timestamp = timestamp
    msg.arbitration_id = arbitration_id
    msg.is_extended_id = is_extended_id
    msg.is_remote_frame = is_remote_frame
    msg.is_error_frame = is_error_frame
    msg.channel = channel
    msg.dlc = dlc
    msg.data = data
    msg.is_fd = is_fd
    msg.is_rx = is_rx
    msg.bitrate_switch = bitrate_switch
    msg.error_state_indicator = error_state_indicator
    return msg
