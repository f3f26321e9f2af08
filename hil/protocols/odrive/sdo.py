"""Discovery (Address, 0x06) and endpoint access (RxSdo 0x04 / TxSdo 0x05) of a simulated
ODrive on firmware 0.6.11, as the maker's ``odrive`` library 0.6.11 (libodrive 0.9.6) uses
them over SocketCAN.

Sources: ODrive's CAN protocol page (Address: Node_ID u8, Serial_Number 48 bits, and from
0.6.11 Connection_ID u8; RxSdo: Opcode u8 (0 read, 1 write), Endpoint_ID u16, a reserved
u8, Value; TxSdo: a reserved u8, Endpoint_ID u16, a reserved u8, Value; writes confirmed
from 0.6.11), ODrive's ``can_enumerate.py`` and ``can_param_access.py`` (ODriveResources),
and libodrive's frames as sent and accepted, recorded over vcan (2026-12-06):

* discovery: an RTR on the broadcast id (node 63) ``0x7E6`` once a second; an answer of 7
  bytes (no Connection_ID) is ignored, one with Connection_ID 0 is found but "not
  connectable" (``NotConnectableException``), any other is connectable;
* connecting: an Address data frame on ``0x7E6``: ``[node_id, serial (6, LE),
  connection_id]``, the connection id chosen by the client (a multiple of 4); libodrive
  then waits for the next discovery answer to carry that id;
* an RxSdo's first byte is ``connection_id | opcode``, its fourth a sequence number; the
  TxSdo answer repeats both (libodrive matches on them), then the value: the read value,
  nothing for a write (its confirmation), a function's outputs;
* endpoint 0 is the descriptor (Fibre): the value is a uint32 offset, 0xFFFFFFFF asks for
  the JSON's version id; each answer carries the next (at most) 4 bytes of the JSON, a
  shorter one ends it.
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable
from dataclasses import dataclass

from hil.protocols.odrive.endpoints import FUNCTION, Endpoint, EndpointFile, json_id

OPCODE_READ, OPCODE_WRITE = 0, 1
#: the opcode's bits of an RxSdo's first byte; the rest carry libodrive's connection id,
#: whose ids are multiples of 4 (recorded)
OPCODE_MASK = 0x03
JSON_VERSION_OFFSET = 0xFFFFFFFF
#: the connection id a drive announces before a client connects: any non-zero one makes
#: libodrive call it connectable; the protocol page gives no value, so this is hil's choice
FIRST_CONNECTION_ID = 1
SDO_VALUE_BYTES = 4


@dataclass
class Address:
    """What an Address message says of a drive: its node id, serial number, connection."""

    node_id: int
    serial_number: int
    connection_id: int = FIRST_CONNECTION_ID

    def payload(self) -> bytes:
        return (bytes([self.node_id]) + self.serial_number.to_bytes(6, "little")
                + bytes([self.connection_id]))

    def take(self, data: bytes) -> None:
        """An Address data frame (set address / connect): taken when it names this drive's
        serial number and node id. Moving to another node id is not simulated (hil's bus
        config fixes it); the connection id is taken when given (7 bytes: connectionless,
        can_enumerate.py)."""
        if (len(data) >= 8 and data[0] == self.node_id
                and int.from_bytes(data[1:7], "little") == self.serial_number):
            self.connection_id = data[7]


@dataclass(frozen=True)
class Backing:
    """How hil backs one endpoint: a reader of its value, a writer (the handler of the
    CAN command that sets the same thing, with its checks), or a function without
    arguments."""

    read: Callable[[], float] | None = None
    write: Callable[[float], None] | None = None
    call: Callable[[], None] | None = None


class EndpointServer:
    """Answers RxSdo frames from the endpoints of the user's file that hil backs."""

    def __init__(self, file: EndpointFile, backings: dict[str, Backing]):
        self.descriptor = file.descriptor()
        self.json_id = json_id(self.descriptor)
        self._endpoints = file.by_id
        self._backings = backings

    def answer(self, data: bytes) -> bytes | None:
        """The TxSdo payload for an RxSdo (its 8-byte buffer), or None: no answer."""
        buffer = data.ljust(8, b"\0")
        opcode, endpoint_id = buffer[0] & OPCODE_MASK, int.from_bytes(buffer[1:3], "little")
        header = buffer[:4]
        if endpoint_id == 0:
            return header + self._descriptor(buffer) if opcode == OPCODE_READ else None
        endpoint = self._endpoints.get(endpoint_id)
        backing = self._backings.get(endpoint.path) if endpoint is not None else None
        if backing is None:
            # An endpoint the file lacks, or one hil does not back: not answered. ODrive's
            # CAN protocol page says nothing of an unknown endpoint id; hil stays silent
            # (a client's read times out) rather than invent an error code.
            return None
        value = self._serve(endpoint, backing, opcode, buffer[4:])
        return None if value is None else header + value

    def _descriptor(self, buffer: bytes) -> bytes:
        offset = int.from_bytes(buffer[4:8], "little")
        if offset == JSON_VERSION_OFFSET:
            return self.json_id.to_bytes(4, "little")
        return self.descriptor[offset:offset + SDO_VALUE_BYTES]

    @staticmethod
    def _serve(endpoint: Endpoint, backing: Backing, opcode: int, value: bytes) -> bytes | None:
        if endpoint.type == FUNCTION:
            # hil backs only functions without inputs or outputs (clear_errors)
            if opcode != OPCODE_WRITE or backing.call is None:
                return None
            backing.call()
            return b""
        layout = struct.Struct(endpoint.format)
        if layout.size > SDO_VALUE_BYTES:
            return None                      # a uint64 does not fit the 4-byte value
        if opcode == OPCODE_READ and backing.read is not None and "r" in endpoint.access:
            return _pack(layout, endpoint.type, backing.read())
        if opcode == OPCODE_WRITE and backing.write is not None and "w" in endpoint.access:
            (written,) = layout.unpack_from(value)
            if isinstance(written, float) and not math.isfinite(written):
                return None                  # NaN / inf: refused, as the cyclic commands do
            backing.write(written)
            return b""
        return None


def _pack(layout: struct.Struct, kind: str, value: float) -> bytes:
    if kind == "float":
        return layout.pack(float(value))
    if kind == "bool":
        return layout.pack(bool(value))
    return layout.pack(int(value))
