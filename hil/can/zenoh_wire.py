"""The wire format of the ``zenoh`` CAN interface: a message of sections of frames.

Wire format of one message (little-endian): one or more sections, each: the channel's
length u8 and its name (UTF-8), sender id u64, the first frame's sequence number u32 (per
sender, wrapping; the frames after it are numbered on), the sender's wall clock at the put
f64 (s since the epoch), the echo: sender id u64 (0: none), first sequence number u32, time
held f32 (s); frame count u16; then each frame: arbitration id u32, flags u8 (1 extended,
2 remote, 4 error), DLC u8, the data bytes (none for a remote frame).

A frame goes in and comes out as its parts (:data:`hil.can.messages.FrameParts`: its
dispatch key and its data), as SocketCAN's ``can_frame`` has a frame (the flags in the id,
the DLC as the data's length): a remote or error frame carries :data:`REMOTE` or
:data:`ERROR` in its key, and a remote frame as many zero bytes as its DLC. Between hil's
own ends no ``can.Message`` is built for a frame (:func:`message_of` builds one for a
receiver that wants it): a cycle's frames went through two builds each, measured as a
large share of a process' time per cycle (docs/performance.md).
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence
from typing import NamedTuple

import can

from hil.can.messages import FrameParts, extended, frame_key, identifier, received_frame

#: every CAN channel's key is below this one
KEY_PREFIX = "hil/can/"
_CHANNEL = struct.Struct("<B")
_HEADER = struct.Struct("<QIdQIfH")
_FRAME = struct.Struct("<IBB")
_EXTENDED, _REMOTE, _ERROR = 1, 2, 4


class Echo(NamedTuple):
    """The message a sender heard last: its sender, its first sequence number, and how long
    it was held before this message was put (s). (Named tuples: a frozen dataclass costs a
    microsecond more a message to make.)"""

    sender: int = 0
    sequence: int = 0
    held: float = 0.0


NO_ECHO = Echo()


#: in a frame's key, as SocketCAN's ``CAN_RTR_FLAG`` and ``CAN_ERR_FLAG`` in its ``can_id``
#: (bits an arbitration id and :data:`hil.can.messages.EXTENDED` leave free)
REMOTE, ERROR = 0x40000000, 0x20000000
#: the key bits of a frame that is not a data frame
NOT_DATA = REMOTE | ERROR


def wire_frame(msg: can.Message) -> FrameParts:
    """``msg`` as the wire's parts: its key (with REMOTE or ERROR where it is such a frame)
    and a copy of its data (a remote frame: as many zero bytes as its DLC)."""
    if msg.is_remote_frame:
        return frame_key(msg) | REMOTE | (ERROR if msg.is_error_frame else 0), bytes(msg.dlc)
    return frame_key(msg) | (ERROR if msg.is_error_frame else 0), bytes(msg.data or b"")


def message_of(frame: FrameParts, timestamp: float, channel, is_rx: bool = True
               ) -> can.Message:
    """The ``can.Message`` of a frame by its wire parts (its own copy of the data)."""
    key, data = frame
    remote = bool(key & REMOTE)
    msg = received_frame(timestamp, *identifier(key), remote, bool(key & ERROR), len(data),
                         b"" if remote else data, channel)
    msg.is_rx = is_rx
    return msg


def encode_frames(channel: str, sender: int, sequence: int, sent_at: float,
                  frames: Sequence[FrameParts], echo: Echo = NO_ECHO) -> bytes:
    """One section of a message: ``frames`` (by their wire parts: :func:`wire_frame`) of
    ``channel``, the first numbered ``sequence``, put at ``sent_at``, echoing ``echo``. A
    message is one or more sections, joined."""
    name = channel.encode()
    parts = [_CHANNEL.pack(len(name)), name,
             _HEADER.pack(sender, sequence & 0xFFFFFFFF, sent_at, echo.sender,
                          echo.sequence & 0xFFFFFFFF, echo.held, len(frames))]
    pack, append = _FRAME.pack, parts.append
    for key, data in frames:
        if key <= 0x7FF:            # a standard data frame: no flags
            append(pack(key, 0, len(data)))
            append(data)
            continue
        arbitration_id, is_extended = identifier(key)
        append(pack(arbitration_id, (_EXTENDED if is_extended else 0)
                    | (_REMOTE if key & REMOTE else 0) | (_ERROR if key & ERROR else 0),
                    len(data)))
        if not key & REMOTE:
            append(data)
    return b"".join(parts)


class Message(NamedTuple):
    """A decoded section: its channel, who put it, its first frame's sequence number, the
    sender's clock at the put, what it echoes, its frames (their wire parts), and whether
    every one of them is a data frame."""

    channel: str
    sender: int
    sequence: int
    sent_at: float
    echo: Echo
    frames: list[FrameParts]
    all_data: bool


def decode_frames(payload: bytes) -> list[Message]:
    """The sections of the message in ``payload``; raise ValueError for anything that is not
    a well-formed message, naming the section and frame."""
    sections, offset = [], 0
    while True:
        section, offset = _decode_section(payload, offset, len(sections) + 1)
        sections.append(section)
        if offset == len(payload):
            return sections


def _decode_section(payload: bytes, offset: int, number: int) -> tuple[Message, int]:
    """The section at ``offset``, and where the next one begins. (Every check is made; the
    words of a refusal are put together only once there is one, and each frame's bounds are
    checked against one length: 11-13 % of a well-formed message's decoding before,
    docs/performance.md, 2026-12-02.)"""
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
    frames: list[FrameParts] = []
    append, unpack, frame_size = frames.append, _FRAME.unpack_from, _FRAME.size
    all_data = True
    offset += _HEADER.size
    for index in range(count):
        if size < offset + frame_size:
            raise ValueError(f"{_where(number, channel)}frame {index + 1} of {count} is cut "
                             "short")
        arbitration_id, flags, dlc = unpack(payload, offset)
        offset += frame_size
        end = offset + (0 if flags & _REMOTE else dlc)
        if dlc > 8 or end > size:
            raise ValueError(f"{_where(number, channel)}frame {index + 1} of {count}: DLC {dlc} "
                             f"does not match {min(size - offset, 8)} data bytes")
        if flags == 0 and arbitration_id <= 0x7FF:      # a standard data frame
            append((arbitration_id, payload[offset:end]))
            offset = end
            continue
        if arbitration_id > (0x1FFFFFFF if flags & _EXTENDED else 0x7FF):
            raise ValueError(f"{_where(number, channel)}frame {index + 1} of {count}: "
                             f"identifier 0x{arbitration_id:X} out of range")
        key = extended(arbitration_id) if flags & _EXTENDED else arbitration_id
        if flags & (_REMOTE | _ERROR):
            all_data = False
            key |= (REMOTE if flags & _REMOTE else 0) | (ERROR if flags & _ERROR else 0)
        append((key, bytes(dlc) if flags & _REMOTE else payload[offset:end]))
        offset = end
    return Message(channel, sender, sequence, sent_at, Echo(echo_sender, echo_sequence, held),
                   frames, all_data), offset


def _where(number: int, channel: str | None = None) -> str:
    """A refusal's prefix: which section (the first goes unnamed) and channel it is in."""
    where = f"section {number}: " if number > 1 else ""
    return where if channel is None else f"{where}channel '{channel}': "
