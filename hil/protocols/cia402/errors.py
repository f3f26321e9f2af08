"""A CANopen drive's errors as CiA 301 keeps them: the error register (0x1001), the
pre-defined error field (0x1003, newest first) and the EMCY each change sends.

CiA 301 7.2.7 and 7.5.2.2/7.5.2.3: an EMCY carries the error code and the error register as
it is with the error in; when errors go, an EMCY "error reset or no error" (0x0000) with
the register as it then is (0 once none is left); bit 0 (generic) of 0x1001 is set while any
error is; 0x1003 sub-index 0 counts the entries, writing 0 there deletes them (anything
else: abort 0x06090030). When an error goes is hil's reading for a drive: a fault at its
reset (controlword bit 7), a silence that did not fault the drive (0x6007 2 or 3) once the
master has enabled it again.

A frame the drive could not take (an RPDO shorter or longer than its mapping, 0x8210 and
0x8220; a SYNC of the wrong length, 0x8240) is an error too: CiA 301 7.5.2.3, 0x1003 holds
"the errors that occurred on the device and were signalled via the EMCY", and 7.5.2.1,
0x1001 the error register the EMCY carries (communication, bit 4). It is in force until a
frame of its kind comes right (CANopenNode's CO_PDO.c resets its RPDO length error at the
next RPDO of the right length; hil's reading does the same for the SYNC's). Whenever errors
go, an EMCY 0x0000 says so with the register as it then is (CiA 301 7.2.7.1: "error reset",
with the errors that remain).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from hil.protocols.cia402 import FRAME_ERRORS, LINK_LOSS     # (module doc)

#: EMCY codes that are not drive faults (CiA 301)
EMCY_PDO_LENGTH = 0x8210            # PDO not processed: shorter than its mapping
EMCY_PDO_LENGTH_EXCEEDED = 0x8220   # PDO longer than its mapping (processed)
EMCY_SYNC_LENGTH = 0x8240
EMCY_NO_ERROR = 0x0000
#: error register of the communication EMCYs: generic + communication
COMMUNICATION_ERROR = 0x11
#: 0x1003's standard error fields in hil's EDS
HISTORY = 8
GENERIC = 0x01
PDO_ERRORS = (EMCY_PDO_LENGTH, EMCY_PDO_LENGTH_EXCEEDED)
#: errors of the master's silence, which a drive may survive without a fault (0x6007 2, 3)
SILENCE = LINK_LOSS


@dataclass
class ErrorRecord:
    """The errors in force (code -> their error register bits) and the history."""

    active: dict[int, int] = field(default_factory=dict)
    history: list[int] = field(default_factory=list)

    @property
    def register(self) -> int:
        """0x1001 now."""
        bits = 0
        for each in self.active.values():
            bits |= each
        return bits | GENERIC if self.active else 0

    def enter(self, code: int, bits: int) -> None:
        """An error occurred: in force, and first in the history."""
        self.active[code] = bits
        self.history.insert(0, code)
        del self.history[HISTORY:]

    def over(self, faulted: bool, enabled: bool) -> bool:
        """Whether the drive's errors in force (not the frame errors) are gone (the module
        doc): none is left to the drive's fault, and a silence the drive survived has been
        followed by its enabling."""
        drive = self.active.keys() - FRAME_ERRORS
        return bool(drive) and not faulted and (enabled or not drive & SILENCE)

    def end(self, codes) -> bool:
        """The errors ``codes`` are gone (those in force); whether any was."""
        gone = [code for code in codes if code in self.active]
        for code in gone:
            del self.active[code]
        return bool(gone)

    def end_drive_errors(self) -> None:
        """The drive's errors are gone (:meth:`over`); frame errors stay in force."""
        self.end(self.active.keys() - FRAME_ERRORS)

    def fields(self) -> list[int]:
        """0x1003 sub-indices 1..HISTORY (0 where no entry)."""
        return self.history + [0] * (HISTORY - len(self.history))
