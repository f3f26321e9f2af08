"""The wire format of the ``zenoh`` CAN interface: a message of sections of frames.

Wire format of one message (little-endian): one or more sections, each: the channel's
length u8 and its name (UTF-8), sender id u64, the first frame's sequence number u32 (per
sender, wrapping; the frames after it are numbered on), the sender's wall clock at the put
f64 (s since the epoch), the echo: sender id u64 (0: none), first sequence number u32, time
held f32 (s); frame count u16; then each frame: identifier u32, flags u8 (1 extended, 2
remote, 4 error, 8 CAN FD, 16 bit-rate switch), data length u8 (a remote frame: its DLC),
the data bytes (none for a remote frame).

A frame goes in and comes out as a :class:`~hil.can.frame.Frame` (stamped with the
sender's clock at the put), as SocketCAN's ``canfd_frame`` has one. Between hil's own ends
no ``can.Message`` is built for a frame (:func:`hil.can.messages.message_of` builds one
for a receiver that wants it): a cycle's frames went through two builds each, measured as a
large share of a process' time per cycle (docs/performance.md,
"Frames as their parts over Zenoh (2026-11-28, issue 48, fifth step)").
"""

from __future__ import annotations

import functools
import math
import struct
from collections.abc import Sequence
from typing import NamedTuple

from hil.can.frame import (CLASSIC_MAX_LENGTH, EXTENDED_IDS, FD_LENGTHS, STANDARD_IDS, Frame,
                           frame_of_fields)

#: every CAN channel's key is below this one
KEY_PREFIX = "hil/can/"
_CHANNEL = struct.Struct("<B")
_HEADER = struct.Struct("<QIdQIfH")
_FRAME = struct.Struct("<IBB")
_EXTENDED, _REMOTE, _ERROR, _FD, _BITRATE_SWITCH = 1, 2, 4, 8, 16
_FLAGS = _EXTENDED | _REMOTE | _ERROR | _FD | _BITRATE_SWITCH
_FD_LENGTHS = frozenset(FD_LENGTHS)


class Echo(NamedTuple):
    """The message a sender heard last: its sender, its first sequence number, and how long
    it was held before this message was put (s). (Named tuples: a frozen dataclass costs
    more a message to make, docs/performance.md,
    "2026-12-06, later: figures from code comments".)"""

    sender: int = 0
    sequence: int = 0
    held: float = 0.0


NO_ECHO = Echo()
#: an Echo from the tuple of its fields, built from C (Echo's own ``__new__`` is a Python
#: call, one a section decoded)
echo_of_fields = functools.partial(tuple.__new__, Echo)


def encode_frames(channel: str, sender: int, sequence: int, sent_at: float,
                  frames: Sequence[Frame], echo: Echo = NO_ECHO) -> bytes:
    """One section of a message: ``frames`` of ``channel``, the first numbered
    ``sequence``, put at ``sent_at``, echoing ``echo``. A message is one or more sections,
    joined."""
    name = channel.encode()
    parts = [_CHANNEL.pack(len(name)), name,
             _HEADER.pack(sender, sequence & 0xFFFFFFFF, sent_at, echo.sender,
                          echo.sequence & 0xFFFFFFFF, echo.held, len(frames))]
    pack, append = _FRAME.pack, parts.append
    for identifier, data, extended, fd, bitrate_switch, remote, error, _ in frames:
        if not (extended or fd or remote or error):      # a classic standard data frame
            append(pack(identifier, 0, len(data)))
            append(data)
            continue
        flags = extended | remote << 1 | error << 2 | fd << 3 | bitrate_switch << 4
        append(pack(identifier, flags, len(data)))
        if not remote:
            append(data)
    return b"".join(parts)


class Message(NamedTuple):
    """A decoded section: its channel, who put it, its first frame's sequence number, the
    sender's clock at the put, what it echoes, and its frames."""

    channel: str
    sender: int
    sequence: int
    sent_at: float
    echo: Echo
    frames: list[Frame]


#: a Message from the tuple of its fields, built from C (as :data:`echo_of_fields`)
message_of_fields = functools.partial(tuple.__new__, Message)


def decode_frames(payload: bytes) -> list[Message]:
    """The sections of the message in ``payload``; raise ValueError for anything that is not
    a well-formed message, naming the section and frame."""
    sections: list[Message] = []
    offset = 0
    while True:
        section, offset = _decode_section(payload, offset, len(sections) + 1)
        sections.append(section)
        if offset == len(payload):
            return sections


def _decode_section(payload: bytes, offset: int, number: int) -> tuple[Message, int]:
    """The section at ``offset``, and where the next one begins. (Every check is made; the
    words of a refusal are put together only once there is one, and each frame's bounds are
    checked against one length: a well-formed message decodes faster so,
    docs/performance.md, "2026-12-02: where a lock-step cycle across processes goes".)"""
    size = len(payload)
    if size < offset + 1:
        raise ValueError(f"{_where(number)}no channel name: the message is empty")
    length = payload[offset]
    offset += 1
    if size < offset + length:
        raise ValueError(f"{_where(number)}the channel's name is cut short")
    try:
        channel = payload[offset:offset + length].decode()
    except UnicodeDecodeError:
        raise ValueError(f"{_where(number)}the channel's name is not UTF-8") from None
    offset += length
    if size < offset + _HEADER.size:
        raise ValueError(f"{_where(number, channel)}{size - offset} bytes is shorter than a "
                         "section header")
    sender, sequence, sent_at, echo_sender, echo_sequence, held, count = \
        _HEADER.unpack_from(payload, offset)
    if count == 0:
        raise ValueError(f"{_where(number, channel)}a section of no frames")
    if not math.isfinite(sent_at):
        raise ValueError(f"{_where(number, channel)}the sender's clock reads {sent_at}")
    if not (math.isfinite(held) and held >= 0):
        raise ValueError(f"{_where(number, channel)}the echo was held {held} s")
    frames: list[Frame] = []
    append, unpack, frame_size = frames.append, _FRAME.unpack_from, _FRAME.size
    offset += _HEADER.size
    for index in range(count):
        if size < offset + frame_size:
            raise ValueError(f"{_where(number, channel)}frame {index + 1} of {count} is cut "
                             "short")
        identifier, flags, length = unpack(payload, offset)
        offset += frame_size
        if flags == 0 and identifier <= STANDARD_IDS:      # a classic standard data frame
            end = offset + length
            if length > CLASSIC_MAX_LENGTH:
                raise ValueError(f"{_where(number, channel)}frame {index + 1} of {count}: DLC "
                                 f"{length} in a classic CAN frame")
            if end > size:
                raise ValueError(_cut(number, channel, index, count, length, size - offset))
            append(frame_of_fields((identifier, payload[offset:end], False, False, False,
                                    False, False, sent_at)))
            offset = end
            continue
        remote = bool(flags & _REMOTE)
        end = offset + (0 if remote else length)
        problem = _flags_problem(flags, identifier, length)
        if problem is not None:
            raise ValueError(f"{_where(number, channel)}frame {index + 1} of {count}: "
                             f"{problem}")
        if end > size:
            raise ValueError(_cut(number, channel, index, count, length, size - offset))
        append(frame_of_fields((identifier, bytes(length) if remote else payload[offset:end],
                                bool(flags & _EXTENDED), bool(flags & _FD),
                                bool(flags & _BITRATE_SWITCH), remote, bool(flags & _ERROR),
                                sent_at)))
        offset = end
    return message_of_fields((channel, sender, sequence, sent_at,
                              echo_of_fields((echo_sender, echo_sequence, held)), frames)), offset


def _flags_problem(flags: int, identifier: int, length: int) -> str | None:
    """What makes a frame's flags, identifier and length no frame of CAN or CAN FD."""
    if flags & ~_FLAGS:
        return f"unknown flags 0x{flags:02X}"
    if identifier > (EXTENDED_IDS if flags & _EXTENDED else STANDARD_IDS):
        return f"identifier 0x{identifier:X} out of range"
    if flags & _FD:
        if flags & _REMOTE:
            return "a CAN FD remote frame"
        if length not in _FD_LENGTHS:
            return f"a CAN FD frame of {length} data bytes"
    elif flags & _BITRATE_SWITCH:
        return "a bit-rate switch without CAN FD"
    elif length > CLASSIC_MAX_LENGTH:
        return f"DLC {length} in a classic CAN frame"
    return None


def _cut(number: int, channel: str, index: int, count: int, length: int, left: int) -> str:
    return (f"{_where(number, channel)}frame {index + 1} of {count}: DLC {length} does not "
            f"match {min(left, 64)} data bytes")


def _where(number: int, channel: str | None = None) -> str:
    """A refusal's prefix: which section (the first goes unnamed) and channel it is in."""
    where = f"section {number}: " if number > 1 else ""
    return where if channel is None else f"{where}channel '{channel}': "
