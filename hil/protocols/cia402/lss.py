"""The LSS slave (CiA 305 layer setting services) of hil's CANopen drives.

A master finds drives by their identity (0x1018: vendor, product, revision, serial) and
gives them a node id and bit timing. Requests on 0x7E5, answers on 0x7E4, 8 bytes, the
command specifier first. As CiA 305 has them and CANopenNode's CO_LSSslave.c implements
them:

* switch state global (0x04): waiting (0) or configuration (1); back in waiting, a drive
  that had no node id takes the one configured (it boots with it: :attr:`on_node_id`);
* switch state selective (0x40-0x43: vendor, product, revision, serial): the drive whose
  identity matches all four goes to configuration and answers 0x44;
* in configuration: configure node id (0x11: 1-127, or 255 for none; error 1 otherwise),
  configure bit timing (0x13: CiA table 0, indices 0-4 and 6-8; error 1 otherwise), activate
  bit timing (0x15, no answer), store configuration (0x17: kept for the run), inquire
  identity (0x5A-0x5D) and node id (0x5E);
* identify remote slave (0x46-0x4B: vendor, product, revision and serial ranges) answered
  0x4F by a drive within all of them; identify non-configured remote slave (0x4C) answered
  0x50 by a drive without a node id;
* fastscan (0x51), by a drive without a node id in waiting: the bits from ``bit_check`` up
  of the identity part ``lss_sub`` compared, 0x4F where they match; at bit 0 the next part
  is ``lss_next``, and a ``lss_next`` below ``lss_sub`` ends the scan in configuration;
  bit_check 0x80 restarts it.

A bit timing is recorded, not applied: a virtual bus has no bit rate to change (hil's
reading). Frames of another length are ignored, as CANopenNode does.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass

WAITING, CONFIGURATION = 0, 1
UNCONFIGURED = 255
#: CiA 305 bit timing table 0: index -> bit/s (5 is reserved; 9 is automatic detection)
BIT_TIMINGS = {0: 1_000_000, 1: 800_000, 2: 500_000, 3: 250_000, 4: 125_000, 6: 50_000,
               7: 20_000, 8: 10_000}
#: command specifiers
SWITCH_GLOBAL, CONFIGURE_NODE_ID, CONFIGURE_BIT_TIMING = 0x04, 0x11, 0x13
ACTIVATE_BIT_TIMING, STORE = 0x15, 0x17
SELECTIVE_FIRST, SELECTIVE_ANSWER = 0x40, 0x44
IDENTIFY_FIRST, IDENTIFY_LAST, IDENTIFIED = 0x46, 0x4B, 0x4F
IDENTIFY_NON_CONFIGURED, NON_CONFIGURED = 0x4C, 0x50
FASTSCAN, FASTSCAN_CONFIRM = 0x51, 0x80
INQUIRE_FIRST, INQUIRE_NODE_ID = 0x5A, 0x5E


@dataclass(frozen=True)
class Identity:
    """0x1018:01-04."""

    vendor: int
    product: int
    revision: int
    serial: int

    def part(self, number: int) -> int:
        return (self.vendor, self.product, self.revision, self.serial)[number]


class LssSlave:
    """One drive's LSS state; :meth:`on_request` takes each 0x7E5 frame."""

    def __init__(self, identity: Identity, node_id: int, send: Callable[[bytes], None],
                 on_node_id: Callable[[int], None]):
        self.identity = identity
        self.state = WAITING
        self.active_node_id = node_id
        self.pending_node_id = node_id
        self.stored_node_id = node_id
        self.bit_timing: int | None = None        # the table index configured, if any
        self._send = send
        #: called (with the new id) when a drive without one takes its configured node id
        self.on_node_id = on_node_id
        self._selective: list[int] = []           # identity parts matched so far (0x40-0x43)
        self._identify: list[bool] = []           # 0x46-0x4B: each range's verdict so far
        self._fastscan_part = 0

    def power_on(self) -> int:
        """A power cycle: waiting, with the node id stored (0x17) as the active one."""
        self.state = WAITING
        self.active_node_id = self.pending_node_id = self.stored_node_id
        self._selective, self._identify, self._fastscan_part = [], [], 0
        return self.active_node_id

    def on_request(self, data: bytes) -> None:
        """One request's data (a frame on 0x7E5)."""
        if len(data) != 8:
            return
        command = data[0]
        if command == SWITCH_GLOBAL:
            self._switch(data[1])
        elif SELECTIVE_FIRST <= command < SELECTIVE_ANSWER:
            self._select(command - SELECTIVE_FIRST, struct.unpack_from("<I", data, 1)[0])
        elif IDENTIFY_FIRST <= command <= IDENTIFY_LAST:
            self._identify_remote(command - IDENTIFY_FIRST, struct.unpack_from("<I", data, 1)[0])
        elif command == IDENTIFY_NON_CONFIGURED:
            if self.active_node_id == UNCONFIGURED:
                self._answer(NON_CONFIGURED)
        elif command == FASTSCAN:
            self._fastscan(*struct.unpack_from("<IBBB", data, 1))
        elif self.state == CONFIGURATION:
            self._configure(command, data)

    def _switch(self, mode: int) -> None:
        if mode == CONFIGURATION:
            self.state = CONFIGURATION
        elif mode == WAITING:
            self.state = WAITING
            if self.active_node_id == UNCONFIGURED and self.pending_node_id != UNCONFIGURED:
                self.active_node_id = self.pending_node_id
                self.on_node_id(self.active_node_id)

    def _select(self, part: int, value: int) -> None:
        if part == 0:
            self._selective = []
        if len(self._selective) != part or value != self.identity.part(part):
            self._selective = []
            return
        self._selective.append(value)
        if part == 3:
            self._selective = []
            self.state = CONFIGURATION
            self._answer(SELECTIVE_ANSWER)

    def _identify_remote(self, step: int, value: int) -> None:
        """Vendor, product (equal), revision low/high, serial low/high (a range each)."""
        if step == 0:
            self._identify = []
        if len(self._identify) != step:
            self._identify = []
            return
        part = min(step, 2) if step < 4 else 3
        own = self.identity.part(part)
        if step < 2:
            verdict = own == value
        elif step in (2, 4):
            verdict = own >= value                 # the range's low end
        else:
            verdict = own <= value                 # its high end
        self._identify.append(verdict)
        if step == 5:
            if all(self._identify):
                self._answer(IDENTIFIED)
            self._identify = []

    def _fastscan(self, id_number: int, bit_check: int, lss_sub: int, lss_next: int) -> None:
        if self.state != WAITING or self.active_node_id != UNCONFIGURED:
            return
        if bit_check == FASTSCAN_CONFIRM:
            self._fastscan_part = 0
            self._answer(IDENTIFIED)
            return
        if bit_check > 31 or lss_sub > 3 or lss_next > 3 or lss_sub != self._fastscan_part:
            return
        mask = (0xFFFFFFFF << bit_check) & 0xFFFFFFFF
        if (self.identity.part(lss_sub) ^ id_number) & mask:
            return
        if bit_check == 0:
            self._fastscan_part = lss_next
            if lss_next < lss_sub:                 # the last part matched: this drive
                self.state = CONFIGURATION
        self._answer(IDENTIFIED)

    def _configure(self, command: int, data: bytes) -> None:
        if command == CONFIGURE_NODE_ID:
            node_id = data[1]
            valid = 1 <= node_id <= 127 or node_id == UNCONFIGURED
            if valid:
                self.pending_node_id = node_id
            self._answer(CONFIGURE_NODE_ID, bytes([0 if valid else 1]))
        elif command == CONFIGURE_BIT_TIMING:
            valid = data[1] == 0 and data[2] in BIT_TIMINGS
            if valid:
                self.bit_timing = data[2]
            self._answer(CONFIGURE_BIT_TIMING, bytes([0 if valid else 1]))
        elif command == STORE:
            self.stored_node_id = self.pending_node_id
            self._answer(STORE, b"\0")
        elif INQUIRE_FIRST <= command < INQUIRE_NODE_ID:
            self._answer(command, struct.pack("<I", self.identity.part(command - INQUIRE_FIRST)))
        elif command == INQUIRE_NODE_ID:
            self._answer(INQUIRE_NODE_ID, bytes([self.active_node_id]))
        # ACTIVATE_BIT_TIMING: nothing to answer, nothing a virtual bus can change

    def _answer(self, command: int, payload: bytes = b"") -> None:
        self._send((bytes([command]) + payload).ljust(8, b"\0"))
