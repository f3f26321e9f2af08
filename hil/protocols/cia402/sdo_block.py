"""SDO block transfers, the server's side (CiA 301 7.2.4.3.9-7.2.4.3.16), which canopen's
SdoServer does not serve.

Upload: the client's initiate (blksize 1-127, protocol switch threshold pst) is answered
with the size and CRC support, or, where 0 < size <= pst, by a normal upload (the switch
CiA 301 allows; CANopenNode does so); then sub-blocks of up to blksize segments, each
acknowledged by the client, and the end with the bytes unused in the last segment and the
CRC. Download: the initiate answered with the server's blksize (127), the segments taken
in sequence (one out of sequence ends the sub-block: the acknowledgement names the last
good one, which the client repeats from), none past the size (a segment that comes when the
bytes taken already fill it: 0x06070012, as CANopenNode's CO_SDOserver.c
validateAndWriteToOD aborts with CO_SDO_AB_DATA_LONG where sizeTran passes sizeInd), the end
checked for the CRC (0x05040004) and the indicated size (0x06070010), then written. CRC-16
as canopen's client computes it (CCITT, the XMODEM variant).
"""

from __future__ import annotations

import binascii
import struct
from collections.abc import Callable

from canopen.sdo import SdoAbortedError
from canopen.sdo.constants import ABORT_CRC_ERROR, ABORT_INVALID_BLOCK_SIZE

#: block transfer command bits (CiA 301)
CRC_SUPPORTED, SIZE_INDICATED = 0x04, 0x02
CS_MASK, INITIATE, END, ACK, START = 0x03, 0, 1, 2, 3
RESPONSE_BLOCK_UPLOAD, RESPONSE_BLOCK_DOWNLOAD = 0xC0, 0xA0
LAST_SEGMENT = 0x80
#: the sub-block size this server asks for (the largest CiA 301 allows)
SERVER_BLOCK_SIZE = 127
ABORT_LENGTH = 0x06070010
#: CiA 301 "data type does not match, length of service parameter too high"
ABORT_LENGTH_TOO_HIGH = 0x06070012
#: the most bytes a block download without indicated size takes into an object of no fixed
#: size (a string, a domain): hil's bound, CiA 301 gives none (CANopenNode's is its buffer's)
MAX_BLOCK_DOWNLOAD = 0x10000
ABORT_ABORTED_BY_CLIENT = 0x80


def crc16(data: bytes) -> int:
    return binascii.crc_hqx(data, 0)


class BlockUpload:
    """One block upload in progress: the object's bytes and how far the client has them."""

    def __init__(self, data: bytes, block_size: int, crc: bool,
                 send: Callable[[bytes], None]):
        if not 1 <= block_size <= 127:
            raise SdoAbortedError(ABORT_INVALID_BLOCK_SIZE)
        self.data, self.block_size, self.crc, self._send = data, block_size, crc, send
        self._acknowledged = 0            # bytes the client has confirmed
        self._ended = False

    def initiate_response(self, index: int, subindex: int) -> bytes:
        command = RESPONSE_BLOCK_UPLOAD | SIZE_INDICATED | (CRC_SUPPORTED if self.crc else 0)
        return struct.pack("<BHBI", command, index, subindex, len(self.data))

    def on_request(self, data: bytes) -> bool:
        """A client frame of this transfer; True once the transfer is over."""
        command = data[0] & CS_MASK
        if command == START and not self._ended:
            self._sub_block()
        elif command == ACK and not self._ended:
            self._acknowledged = min(len(self.data), self._acknowledged + 7 * data[1])
            if not 1 <= data[2] <= 127:
                raise SdoAbortedError(ABORT_INVALID_BLOCK_SIZE)
            self.block_size = data[2]
            if self._acknowledged >= len(self.data):
                self._end()
            else:
                self._sub_block()
        elif command == END and self._ended:
            return True
        return False

    def _sub_block(self) -> None:
        start = self._acknowledged
        for seq in range(1, self.block_size + 1):
            chunk = self.data[start:start + 7]
            last = start + 7 >= len(self.data)
            self._send(bytes([seq | (LAST_SEGMENT if last else 0)]) + chunk.ljust(7, b"\0"))
            start += 7
            if last:
                break

    def _end(self) -> None:
        unused = (7 - len(self.data) % 7) % 7
        crc = crc16(self.data) if self.crc else 0
        self._send(struct.pack("<BH", RESPONSE_BLOCK_UPLOAD | unused << 2 | END, crc)
                   .ljust(8, b"\0"))
        self._ended = True


class BlockDownload:
    """One block download in progress: the bytes taken so far, in sequence."""

    def __init__(self, index: int, subindex: int, size: int | None, crc: bool,
                 send: Callable[[bytes], None], object_size: int | None = None):
        self.index, self.subindex, self.size, self.crc = index, subindex, size, crc
        #: the bytes the transfer may bring: the size it indicated, else the object's
        self.limit = size if size is not None else object_size or MAX_BLOCK_DOWNLOAD
        self._send = send
        self.buffer = bytearray()
        self._next = 1                   # the sequence number expected
        self._last_good = 0
        self.receiving = True            # segments (False: the end frame is next)

    def initiate_response(self) -> bytes:
        command = RESPONSE_BLOCK_DOWNLOAD | (CRC_SUPPORTED if self.crc else 0)
        return struct.pack("<BHBB", command, self.index, self.subindex, SERVER_BLOCK_SIZE)

    def segment(self, data: bytes) -> None:
        seq, last = data[0] & 0x7F, bool(data[0] & LAST_SEGMENT)
        in_sequence = seq == self._next
        if in_sequence and len(self.buffer) >= self.limit:
            raise SdoAbortedError(ABORT_LENGTH_TOO_HIGH)     # past what it said it brings
        if in_sequence:
            self.buffer += data[1:8]
            self._last_good, self._next = seq, seq + 1
        else:
            self._next = -1              # out of sequence: the rest of the sub-block is lost
        if seq == SERVER_BLOCK_SIZE or last:
            self._send(struct.pack("<BBB", RESPONSE_BLOCK_DOWNLOAD | ACK, self._last_good,
                                   SERVER_BLOCK_SIZE).ljust(8, b"\0"))
            self.receiving = not (last and in_sequence)
            self._next, self._last_good = 1, 0

    def end(self, data: bytes) -> bytes:
        """The end frame: the object's bytes, checked (the caller writes them)."""
        unused = (data[0] >> 2) & 0x07
        payload = bytes(self.buffer[:len(self.buffer) - unused])
        if self.crc and struct.unpack_from("<H", data, 1)[0] != crc16(payload):
            raise SdoAbortedError(ABORT_CRC_ERROR)
        if self.size is not None and self.size != len(payload):
            raise SdoAbortedError(ABORT_LENGTH)
        return payload
