"""The wire format of the ``zenoh`` CAN interface: a message of sections of frames.

Wire format of one message (little-endian): one or more sections, each: the channel's
length u8 and its name (UTF-8), sender id u64, the first frame's sequence number u32 (per
sender, wrapping; the frames after it are numbered on), the sender's wall clock at the put
f64 (s since the epoch), the echo: sender id u64 (0: none), first sequence number u32, time
held f32 (s); frame count u16; then each frame: arbitration id u32, flags u8 (1 extended,
2 remote, 4 error), DLC u8, the data bytes (none for a remote frame).
"""

from __future__ import annotations

import math
import struct
from collections.abc import Sequence
from typing import NamedTuple

import can

from hil.can.messages import received_frame

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


def encode_frames(channel: str, sender: int, sequence: int, sent_at: float,
                  frames: Sequence[can.Message], echo: Echo = NO_ECHO) -> bytes:
    """One section of a message: ``frames`` of ``channel``, the first numbered ``sequence``,
    put at ``sent_at``, echoing ``echo``. A message is one or more sections, joined."""
    name = channel.encode()
    parts = [_CHANNEL.pack(len(name)), name,
             _HEADER.pack(sender, sequence & 0xFFFFFFFF, sent_at, echo.sender,
                          echo.sequence & 0xFFFFFFFF, echo.held, len(frames))]
    for msg in frames:
        flags = ((_EXTENDED if msg.is_extended_id else 0)
                 | (_REMOTE if msg.is_remote_frame else 0) | (_ERROR if msg.is_error_frame else 0))
        parts.append(_FRAME.pack(msg.arbitration_id, flags, msg.dlc))
        if not msg.is_remote_frame:
            parts.append(bytes(msg.data or b""))
    return b"".join(parts)


class Message(NamedTuple):
    """A decoded section: its channel, who put it, its first frame's sequence number, the
    sender's clock at the put, what it echoes, and its frames."""

    channel: str
    sender: int
    sequence: int
    sent_at: float
    echo: Echo
    frames: list[can.Message]


def decode_frames(payload: bytes, arrived: float) -> list[Message]:
    """The sections of the message in ``payload``, their frames stamped ``arrived``; raise
    ValueError for anything that is not a well-formed message, naming the section and
    frame."""
    sections, offset = [], 0
    while True:
        section, offset = _decode_section(payload, offset, arrived, len(sections) + 1)
        sections.append(section)
        if offset == len(payload):
            return sections


def _decode_section(payload: bytes, offset: int, arrived: float, number: int
                    ) -> tuple[Message, int]:
    """The section at ``offset``, and where the next one begins."""
    where = f"section {number}: " if number > 1 else ""
    if len(payload) < offset + 1:
        raise ValueError(f"{where}no channel name: the message is empty")
    length = payload[offset]
    offset += 1
    if len(payload) < offset + length:
        raise ValueError(f"{where}the channel's name is cut short")
    try:
        channel = payload[offset:offset + length].decode()
    except UnicodeDecodeError:
        raise ValueError(f"{where}the channel's name is not UTF-8") from None
    offset += length
    where = f"{where}channel '{channel}': "
    if len(payload) < offset + _HEADER.size:
        raise ValueError(f"{where}{len(payload) - offset} bytes is shorter than a section "
                         "header")
    sender, sequence, sent_at, echo_sender, echo_sequence, held, count = \
        _HEADER.unpack_from(payload, offset)
    if count == 0:
        raise ValueError(f"{where}a section of no frames")
    if not math.isfinite(sent_at):
        raise ValueError(f"{where}the sender's clock reads {sent_at}")
    if not (math.isfinite(held) and held >= 0):
        raise ValueError(f"{where}the echo was held {held} s")
    frames = []
    offset += _HEADER.size
    for index in range(count):
        if len(payload) < offset + _FRAME.size:
            raise ValueError(f"{where}frame {index + 1} of {count} is cut short")
        arbitration_id, flags, dlc = _FRAME.unpack_from(payload, offset)
        offset += _FRAME.size
        remote = bool(flags & _REMOTE)
        length = 0 if remote else dlc
        if dlc > 8 or len(payload) < offset + length:
            raise ValueError(f"{where}frame {index + 1} of {count}: DLC {dlc} does not match "
                             f"{min(len(payload) - offset, 8)} data bytes")
        limit = 0x1FFFFFFF if flags & _EXTENDED else 0x7FF
        if arbitration_id > limit:
            raise ValueError(f"{where}frame {index + 1} of {count}: identifier "
                             f"0x{arbitration_id:X} out of range")
        frames.append(received_frame(arrived, arbitration_id, bool(flags & _EXTENDED), remote,
                                     bool(flags & _ERROR), dlc, payload[offset:offset + length],
                                     channel))
        offset += length
    return Message(channel, sender, sequence, sent_at, Echo(echo_sender, echo_sequence, held),
                   frames), offset
