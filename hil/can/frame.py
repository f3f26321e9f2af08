"""The one CAN frame value of hil, and the frame specification a protocol declares.

:class:`Frame` is what every protocol handler takes and every sender gives, from the wire
codecs (:mod:`hil.can.zenoh_wire`, :mod:`hil.can.messages` for python-can's ``Message``) to
the logs: classic CAN (ISO 11898-1: 11- or 29-bit identifier, 0-8 data bytes, remote
frames) and CAN FD (up to 64 data bytes in the lengths a DLC can say, the bit-rate switch).
It is a named tuple: one is made per frame sent and received, and a tuple subclass is made
from C (a frozen dataclass sets each field through ``object.__setattr__``, about four
times the cost on a path that carries a cycle's 20-200 frames).

:class:`FrameSpec` is a frame as a protocol declares it, not as sent: its identifier,
length, rate and what it is, for the bus-load model, ``hil describe``, the bus config's
checks and the replay.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import NamedTuple

#: the largest 11-bit (standard) and 29-bit (extended) identifiers, ISO 11898-1
STANDARD_IDS = 0x7FF
EXTENDED_IDS = 0x1FFFFFFF
#: the data lengths a CAN FD frame can have: the DLC's 16 codes (ISO 11898-1:2015, table 5)
FD_LENGTHS = (0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64)
CLASSIC_MAX_LENGTH = 8


class Frame(NamedTuple):
    """One CAN frame.

    ``timestamp`` is the time its bus gave it: a python-can message's (its receive time),
    a Zenoh message's put (the sender's wall clock, which the link's accounting reads); 0.0
    on a frame being sent and on one handed over inside a process (``hil-virtual``, a Zenoh
    bus' neighbour), which no clock stamped (no receiver of hil's reads it: each keeps its
    own clock). ``data`` is immutable: a frame may be handed to many receivers as it is."""

    identifier: int
    data: bytes = b""
    #: a 29-bit identifier (an extended frame); False: an 11-bit one
    extended: bool = False
    #: a CAN FD frame (FDF set): up to 64 data bytes, in the lengths of FD_LENGTHS
    fd: bool = False
    #: CAN FD's bit-rate switch (BRS): the data phase at the bus' data bit rate
    bitrate_switch: bool = False
    #: a remote frame (RTR): a request for the frame of its identifier, which carries no
    #: data: its ``data`` is as many zero bytes as the length it requests (its DLC), as
    #: SocketCAN's ``can_frame`` has it
    remote: bool = False
    #: an error frame, as python-can and SocketCAN report bus errors (CAN_ERR_FLAG)
    error: bool = False
    timestamp: float = 0.0

    @property
    def length(self) -> int:
        """Its data length in bytes (a remote frame: the length it requests)."""
        return len(self.data)

    def problem(self) -> str | None:
        """What makes this frame one no CAN controller sends (None: nothing), in words."""
        limit = EXTENDED_IDS if self.extended else STANDARD_IDS
        if not 0 <= self.identifier <= limit:
            return (f"identifier 0x{self.identifier:X} does not fit "
                    f"{'29' if self.extended else '11'} bits")
        if self.fd:
            if self.remote:
                return "CAN FD has no remote frames"
            if len(self.data) not in FD_LENGTHS:
                return (f"a CAN FD frame carries one of {FD_LENGTHS} data bytes, not "
                        f"{len(self.data)}")
        elif len(self.data) > CLASSIC_MAX_LENGTH:
            return f"a classic CAN frame carries 0..8 data bytes, not {len(self.data)}"
        elif self.bitrate_switch:
            return "only a CAN FD frame switches its bit rate"
        return None

    def __str__(self) -> str:
        width = 8 if self.extended else 3
        kind = " FD" if self.fd else ""
        kind += " BRS" if self.bitrate_switch else ""
        kind += " RTR" if self.remote else ""
        return f"0x{self.identifier:0{width}X}{kind} [{self.data.hex(' ')}]"


#: a Frame from the tuple of all its fields (identifier, data, extended, fd, bitrate_switch,
#: remote, error, timestamp), built from C: for the transports' per-frame paths
frame_of_fields = functools.partial(tuple.__new__, Frame)


@dataclass(frozen=True)
class FrameSpec:
    """A frame a protocol's drive or master uses on a bus, as the protocol declares it."""

    identifier: int
    #: data bytes (a remote frame: 0)
    length: int
    #: frames per second; 0 for a frame sent only on events (an SDO, an NMT command)
    rate: float
    #: the frame in the protocol's own words ("TPDO1", "SYNC", "Set_Input_Pos")
    what: str = ""
    extended: bool = False
    fd: bool = False
    bitrate_switch: bool = False
