"""The subframes of moteus' CAN frames (mjlib's multiplex register protocol), both ways.

Sources: docs/protocol/can.md of github.com/mjbots/moteus ("Subframes", "Example"), and the
server the firmware runs, mjlib's ``multiplex/micro_server.cc`` (github.com/mjbots/mjlib):

* a subframe starts with its type, a varuint; 0x00-0x0f write, 0x10-0x1f read, 0x20-0x2f
  reply, the two low bits a register count (0: a varuint count follows), bits 2-3 the value
  type (int8, int16, int32, float); then the first register (varuint) and, for writes and
  replies, the values, least significant byte first;
* 0x30 write error and 0x31 read error: the register and the error (varuints): 1 an
  unknown register, 2 one not writable;
* 0x50 NOP, also the padding up to a CAN FD length.

How the firmware serves a frame (``ProcessSubframes``, ``ProcessSubframeWrite``,
``ProcessSubframeRead``): subframes in order; a write of an unknown or read-only register
adds a write error to the reply and goes on; a read answers with one reply subframe of the
type and count asked, unless a register of it cannot be read: then the reply subframe is
taken back, a read error names that register, and the rest of the frame is dropped; a
malformed subframe (a varuint or a value cut short) or an unknown subframe type drops the
rest of the frame. Without the reply bit nothing is answered.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterator
from dataclasses import dataclass

from hil.can.frame import FD_LENGTHS
from hil.protocols.moteus.registers import TYPES

WRITE, READ, REPLY = 0x00, 0x10, 0x20
WRITE_ERROR, READ_ERROR = 0x30, 0x31
NOP = 0x50
#: error numbers of 0x30/0x31 (micro_server.cc: ``EmitWriteError(.., 1)`` for
#: kUnknownRegister, 2 for kNotWriteable; a failed ``Read`` returns 1)
UNKNOWN_REGISTER, NOT_WRITABLE = 1, 2
#: a reply fills one CAN FD frame at most (the firmware's ``properties().max_size``, 64):
#: hil's choice, a write error that would not fit is left out, and a read ends the frame
MAX_REPLY = 64


class RegisterServer(ABC):
    """What serves the registers (the firmware's ``MicroServer::Server``): raw values as the
    subframe carries them (int or float by ``kind``)."""

    @abstractmethod
    def write(self, register: int, raw: int | float, kind: int) -> int:
        """Take a value; 0, or the error number the reply names."""

    @abstractmethod
    def read(self, register: int, kind: int) -> int | float | None:
        """A value of type ``kind``; None: a register it cannot read (error 1)."""


def varuint(value: int) -> bytes:
    """``value`` as a varuint (can.md "Common definitions": 7 bits a byte, LSB first)."""
    out = bytearray()
    while True:
        byte, value = value & 0x7F, value >> 7
        out.append(byte | (0x80 if value else 0))
        if not value:
            return bytes(out)


def read_varuint(data: bytes, offset: int) -> tuple[int, int] | None:
    """(value, next offset), or None for one cut short or longer than 5 bytes."""
    value = 0
    for index in range(5):
        if offset + index >= len(data):
            return None
        byte = data[offset + index]
        value |= (byte & 0x7F) << (7 * index)
        if not byte & 0x80:
            return value, offset + index + 1
    return None


def pad(data: bytes) -> bytes:
    """A payload padded with NOPs up to the next CAN FD length (can.md "Subframes"; the
    firmware's ``AsyncWrite``)."""
    length = next(size for size in FD_LENGTHS if size >= len(data))
    return data + bytes([NOP]) * (length - len(data))


def subframe(base: int, kind: int, start: int, count: int) -> bytes:
    """The head of a write, read or reply subframe: its count in the two low bits where it
    fits, else as a varuint."""
    if 0 < count <= 3:
        return bytes([base | kind << 2 | count]) + varuint(start)
    return bytes([base | kind << 2]) + varuint(count) + varuint(start)


def write(kind: int, start: int, raws: list[int | float]) -> bytes:
    return subframe(WRITE, kind, start, len(raws)) + b"".join(TYPES[kind].pack(raw)
                                                             for raw in raws)


def read(kind: int, start: int, count: int) -> bytes:
    return subframe(READ, kind, start, count)


@dataclass(frozen=True)
class Values:
    """A write or reply subframe, parsed: each register with its raw value."""

    base: int
    kind: int
    values: dict[int, int | float]


@dataclass(frozen=True)
class Subframe:
    """One subframe as it stands in a frame: a write, read or reply (its first register,
    its count, the values of a write or reply); an error's ``start`` is its register and
    ``count`` its error number."""

    code: int
    start: int
    count: int
    raws: tuple[int | float, ...] = ()

    @property
    def base(self) -> int:
        return self.code & 0xF0

    @property
    def kind(self) -> int:
        return (self.code >> 2) & 0x03


def _varuints(data: bytes, offset: int, count: int) -> tuple[list[int], int] | None:
    found = []
    for _ in range(count):
        value = read_varuint(data, offset)
        if value is None:
            return None
        found.append(value[0])
        offset = value[1]
    return found, offset


def subframes(data: bytes) -> Iterator[Subframe]:
    """A frame's subframes in order, NOPs skipped, up to where it stops making sense: a
    varuint or a value cut short, or a subframe type that is none of these (the firmware
    drops the rest of the frame there too)."""
    offset = 0
    while offset < len(data):
        code = data[offset]
        offset += 1
        if code == NOP:
            continue
        if code in (WRITE_ERROR, READ_ERROR):
            found = _varuints(data, offset, 2)
            if found is None:
                return
            (register, error), offset = found
            yield Subframe(code, register, error)
            continue
        if code & 0xF0 not in (WRITE, READ, REPLY):
            return                          # an unknown subframe (or a stream)
        head = _varuints(data, offset, 1 if code & 0x03 else 2)
        if head is None:
            return
        numbers, offset = head
        count, start = (code & 0x03, numbers[0]) if code & 0x03 else numbers
        raws: tuple = ()
        if code & 0xF0 != READ:
            size = TYPES[(code >> 2) & 0x03].size
            if offset + size * count > len(data):
                return
            raws = tuple(TYPES[(code >> 2) & 0x03].unpack_from(data, offset + size * index)[0]
                         for index in range(count))
            offset += size * count
        yield Subframe(code, start, count, raws)


def serve(data: bytes, server: RegisterServer, respond: bool) -> bytes:
    """The reply's subframes to one frame's (the module doc); writes reach ``server`` in
    order either way."""
    reply = bytearray()
    for part in subframes(data):
        if part.base == WRITE:
            for index, raw in enumerate(part.raws):
                error = server.write(part.start + index, raw, part.kind)
                answer = (bytes([WRITE_ERROR]) + varuint(part.start + index) + varuint(error)
                          if error else b"")
                if len(reply) + len(answer) <= MAX_REPLY:
                    reply += answer
        elif part.base != READ:
            break                            # a client's reply or error: no subframe of its
        elif respond:                        # hil's choice: a read without the reply bit
            if part.count * TYPES[part.kind].size > MAX_REPLY:     # is skipped
                break
            answered = _serve_read(server, part)
            if len(reply) + len(answered) > MAX_REPLY:
                break
            reply += answered
            if answered[0] == READ_ERROR:
                break
    return bytes(reply) if respond else b""


def _serve_read(server: RegisterServer, part: Subframe) -> bytes:
    out = bytearray([REPLY | (part.code & 0x0F)])
    if not part.code & 0x03:
        out += varuint(part.count)
    out += varuint(part.start)
    for register in range(part.start, part.start + part.count):
        raw = server.read(register, part.kind)
        if raw is None:
            return bytes([READ_ERROR]) + varuint(register) + varuint(UNKNOWN_REGISTER)
        out += TYPES[part.kind].pack(raw)
    return bytes(out)


def parse(data: bytes) -> list[Values | tuple[int, int, int]]:
    """Every write and reply subframe of a frame (as :class:`Values`) and every error (as
    (0x30 or 0x31, register, error)); reads are skipped."""
    found: list[Values | tuple[int, int, int]] = []
    for part in subframes(data):
        if part.code in (WRITE_ERROR, READ_ERROR):
            found.append((part.code, part.start, part.count))
        elif part.base != READ:
            found.append(Values(part.base, part.kind, {part.start + index: raw for index, raw
                                                       in enumerate(part.raws)}))
    return found
