"""The SDO server of hil's CANopen drives: canopen's, with the checks of a real one."""

from __future__ import annotations

import struct

import canopen
from canopen.sdo import SdoServer
from canopen.sdo.constants import (
    ABORT_INVALID_COMMAND_SPECIFIER, EXPEDITED, NO_MORE_DATA, REQUEST_ABORTED,
    REQUEST_BLOCK_DOWNLOAD, REQUEST_BLOCK_UPLOAD, REQUEST_DOWNLOAD, REQUEST_SEGMENT_DOWNLOAD,
    REQUEST_SEGMENT_UPLOAD, REQUEST_UPLOAD, RESPONSE_ABORTED, SIZE_SPECIFIED,
)

STOPPED = "STOPPED"


class DriveSdoServer(SdoServer):
    """canopen's SDO server, with the checks of a real one: 8-byte requests only, silent in
    STOPPED, segments only within a segmented transfer (canopen keeps no such state)."""

    def __init__(self, rx_cobid: int, tx_cobid: int, node: canopen.LocalNode):
        super().__init__(rx_cobid, tx_cobid, node)
        self._segmented: int | None = None     # REQUEST_SEGMENT_UPLOAD/_DOWNLOAD in progress

    def on_request(self, can_id: int, data: bytes, timestamp: float) -> None:
        node = self._node
        if len(data) != 8:
            node.refuse(can_id, f"an SDO request of {len(data)} bytes (CiA 301: 8)")
            return
        if node.nmt.state == STOPPED:
            return
        specifier = data[0] & 0xE0
        if specifier in (REQUEST_SEGMENT_UPLOAD, REQUEST_SEGMENT_DOWNLOAD):
            if specifier != self._segmented:
                self.abort(ABORT_INVALID_COMMAND_SPECIFIER)
                return
        elif specifier == REQUEST_BLOCK_DOWNLOAD:
            # not supported, as canopen's (whose refusal logs an error for a valid request)
            _, self._index, self._subindex = struct.unpack_from("<BHB", data)
            self.abort(ABORT_INVALID_COMMAND_SPECIFIER)
            return
        elif specifier in (REQUEST_UPLOAD, REQUEST_DOWNLOAD, REQUEST_BLOCK_UPLOAD,
                           REQUEST_ABORTED):
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
        self._segmented = None
        # canopen's abort, but a segment request carries no index: it names the transfer's
        # (0 before any), where canopen's would fail to pack None
        data = struct.pack("<BHBL", RESPONSE_ABORTED, self._index or 0, self._subindex or 0,
                           abort_code)
        self.send_response(data)
