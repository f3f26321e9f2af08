"""hil's :class:`~hil.can.frame.Frame` to and from python-can's ``can.Message``, slot by slot.

``can.Message(...)`` spends much of its time on keyword handling; the builders here fill
the slots directly and do in less time what the constructor does for the same arguments
(docs/performance.md, "How the cycle got here (measured at the time, on earlier commits)"),
for the frames that cross to a python-can receiver (SocketCAN, a log writer, a user's
listener). ``tests/test_virtual_bus.py`` pins them against the constructor, field by field,
so a slot python-can adds cannot be left unset.
"""

from __future__ import annotations

import can

from hil.can.frame import Frame, frame_of_fields

_new_message = can.Message.__new__


def frame_of(msg: can.Message, timestamp: float | None = None) -> Frame:
    """The frame ``msg`` carries (its own copy of the data; a remote frame: as many zero
    bytes as its DLC), stamped ``timestamp`` (default: the message's)."""
    data = bytes(msg.dlc) if msg.is_remote_frame else bytes(msg.data or b"")
    return frame_of_fields((msg.arbitration_id, data, msg.is_extended_id, msg.is_fd,
                            msg.bitrate_switch, msg.is_remote_frame, msg.is_error_frame,
                            msg.timestamp if timestamp is None else timestamp))


def message_of(frame: Frame, channel=None, is_rx: bool = False,
               timestamp: float | None = None) -> can.Message:
    """What ``can.Message(timestamp=..., arbitration_id=..., is_extended_id=..., ...)``
    builds for ``frame`` (its data in a bytearray of its own) on ``channel``, stamped
    ``timestamp`` (default: the frame's)."""
    data = bytearray() if frame.remote else bytearray(frame.data)
    return _filled(_new_message(can.Message),
                   frame.timestamp if timestamp is None else timestamp, frame.identifier,
                   frame.extended, frame.remote, frame.error, channel, len(frame.data), data,
                   frame.fd, is_rx, frame.bitrate_switch, False)


def received_copy(msg: can.Message, timestamp: float, channel, is_rx: bool) -> can.Message:
    """A receiver's own copy of ``msg`` (its own data), stamped ``timestamp`` on
    ``channel``."""
    return _filled(_new_message(can.Message), timestamp, msg.arbitration_id,
                   msg.is_extended_id, msg.is_remote_frame, msg.is_error_frame, channel,
                   msg.dlc, bytearray(msg.data), msg.is_fd, is_rx, msg.bitrate_switch,
                   msg.error_state_indicator)


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
