"""The SDO server of hil's CANopen drives: canopen's, with the checks of a real one."""

from __future__ import annotations

import struct
import time

import canopen
from canopen.sdo import SdoAbortedError, SdoServer
from canopen.sdo.constants import (
    ABORT_INVALID_COMMAND_SPECIFIER, ABORT_NOT_IN_OD, EXPEDITED, NO_MORE_DATA, REQUEST_ABORTED,
    REQUEST_BLOCK_DOWNLOAD, REQUEST_BLOCK_UPLOAD, REQUEST_DOWNLOAD, REQUEST_SEGMENT_DOWNLOAD,
    REQUEST_SEGMENT_UPLOAD, REQUEST_UPLOAD, RESPONSE_ABORTED, SIZE_SPECIFIED,
)

from hil.protocols.cia402.sdo_block import (CRC_SUPPORTED, CS_MASK, END, INITIATE,
                                            SIZE_INDICATED, BlockDownload, BlockUpload)

STOPPED = "STOPPED"
#: a transfer in progress is aborted after this silence of its client (s; CANopenNode's
#: example configuration: 1000 ms)
SERVER_TIMEOUT = 1.0
ABORT_TIMEOUT = 0x05040000


class DriveSdoServer(SdoServer):
    """canopen's SDO server, with the checks of a real one: 8-byte requests only, silent in
    STOPPED, segments only within a segmented transfer (canopen keeps no such state)."""

    def __init__(self, rx_cobid: int, tx_cobid: int, node: canopen.LocalNode):
        super().__init__(rx_cobid, tx_cobid, node)
        self._segmented: int | None = None     # REQUEST_SEGMENT_UPLOAD/_DOWNLOAD in progress
        self._block: BlockUpload | BlockDownload | None = None      # (:mod:`.sdo_block`)
        self._last_request = 0.0               # when a transfer in progress last heard

    def expire(self, now: float) -> None:
        """Abort a transfer whose client has been silent for SERVER_TIMEOUT (CiA 301 abort
        0x05040000 "SDO protocol timed out"; called on the drive's clock, under its lock)."""
        if (self._segmented is not None or self._block is not None) and \
                now - self._last_request > SERVER_TIMEOUT:
            self.abort(ABORT_TIMEOUT)

    def on_request(self, can_id: int, data: bytes, timestamp: float) -> None:
        node = self._node
        if len(data) != 8:
            node.refuse(can_id, f"an SDO request of {len(data)} bytes (CiA 301: 8)")
            return
        if node.nmt.state == STOPPED:
            return
        self._last_request = time.monotonic()
        if isinstance(self._block, BlockDownload) and self._block.receiving \
                and data[0] != REQUEST_ABORTED:
            try:
                self._block.segment(data)      # a sub-block's segment: no command specifier
            except SdoAbortedError as exc:
                self._block = None
                self.abort(exc.code)
            return
        specifier = data[0] & 0xE0
        if specifier in (REQUEST_BLOCK_UPLOAD, REQUEST_BLOCK_DOWNLOAD):
            self._segmented = None
            try:
                self._on_block(specifier, bytes(data))
            except SdoAbortedError as exc:
                self.abort(exc.code)
            except KeyError:
                self.abort(ABORT_NOT_IN_OD)
            return
        self._block = None                     # any other request ends a block transfer
        if specifier in (REQUEST_SEGMENT_UPLOAD, REQUEST_SEGMENT_DOWNLOAD):
            if specifier != self._segmented:
                self.abort(ABORT_INVALID_COMMAND_SPECIFIER)
                return
        elif specifier in (REQUEST_UPLOAD, REQUEST_DOWNLOAD, REQUEST_ABORTED):
            self._segmented = None            # a new request ends any transfer in progress
        if specifier == REQUEST_DOWNLOAD and data[0] & EXPEDITED and not data[0] & SIZE_SPECIFIED:
            data = self._sized(bytes(data))
        buffer = self._buffer
        super().on_request(can_id, data, timestamp)
        if self._buffer is not buffer and specifier in (REQUEST_UPLOAD, REQUEST_DOWNLOAD):
            # canopen started a segmented transfer (it made a new buffer)
            self._segmented = (REQUEST_SEGMENT_UPLOAD if specifier == REQUEST_UPLOAD
                               else REQUEST_SEGMENT_DOWNLOAD)
        elif specifier == REQUEST_SEGMENT_UPLOAD and not self._buffer:
            self._segmented = None            # the last segment went out
        elif specifier == REQUEST_SEGMENT_DOWNLOAD and data[0] & NO_MORE_DATA:
            self._segmented = None

    def _on_block(self, specifier: int, data: bytes) -> None:
        """A block upload or download frame (its initiate starts one, replacing any)."""
        node = self._node
        # the client's subcommand: bits 0-1 in an upload, bit 0 alone in a download (bit 1
        # there says the size is indicated)
        command = data[0] & (CS_MASK if specifier == REQUEST_BLOCK_UPLOAD else END)
        if command == INITIATE and specifier == REQUEST_BLOCK_UPLOAD:
            _, self._index, self._subindex, size, threshold = struct.unpack_from("<BHBBB", data)
            value = node.get_data(self._index, self._subindex, check_readable=True)
            if 0 < len(value) <= threshold:   # the protocol switch: a normal upload
                self._block, before = None, self._buffer
                super().on_request(self.rx_cobid, data, 0.0)
                self._segmented = REQUEST_SEGMENT_UPLOAD if self._buffer is not before else None
                return
            self._block = BlockUpload(value, size, bool(data[0] & CRC_SUPPORTED),
                                      self.send_response)
            self.send_response(self._block.initiate_response(self._index, self._subindex))
        elif command == INITIATE:             # block download
            _, self._index, self._subindex, size = struct.unpack_from("<BHBI", data)
            entry = node._find_object(self._index, self._subindex)
            if not entry.writable:
                raise SdoAbortedError(0x06010002)
            self._block = BlockDownload(self._index, self._subindex,
                                        size if data[0] & SIZE_INDICATED else None,
                                        bool(data[0] & CRC_SUPPORTED), self.send_response,
                                        len(entry) // 8 if entry.fixed_size else None)
            self.send_response(self._block.initiate_response())
        elif isinstance(self._block, BlockUpload) and specifier == REQUEST_BLOCK_UPLOAD:
            if self._block.on_request(data):
                self._block = None
        elif isinstance(self._block, BlockDownload) and command == END:
            block, self._block = self._block, None
            node.set_data(block.index, block.subindex, block.end(data), check_writable=True)
            self.send_response(bytes([0xA0 | END]).ljust(8, b"\0"))
        else:
            raise SdoAbortedError(ABORT_INVALID_COMMAND_SPECIFIER)

    def _sized(self, data: bytes) -> bytes:
        """An expedited download without size indication (0x22) takes the object's size
        (CiA 301 7.2.4.3.3: "size ... not indicated": the data is the object's), where
        canopen would write all 4 bytes into a smaller object; an object unknown or not of
        a fixed size stays as it came (its checks answer)."""
        index, subindex = struct.unpack_from("<HB", data, 1)
        try:
            variable = self._node.object_dictionary[index]
            if not isinstance(variable, canopen.objectdictionary.ODVariable):
                variable = variable[subindex]
        except KeyError:
            return data
        size = len(variable.encode_raw(0)) if variable.fixed_size else 0
        if not 1 <= size <= 4:
            return data
        return bytes([data[0] | SIZE_SPECIFIED | (4 - size) << 2]) + data[1:]

    def abort(self, abort_code: int = 0x08000000) -> None:
        self._segmented, self._block = None, None
        # canopen's abort, but a segment request carries no index: it names the transfer's
        # (0 before any), where canopen's would fail to pack None
        data = struct.pack("<BHBL", RESPONSE_ABORTED, self._index or 0, self._subindex or 0,
                           abort_code)
        self.send_response(data)
