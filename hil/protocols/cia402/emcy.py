"""What a simulated CiA 402 drive signals of its errors (CiA 301 7.2.7): the error record
(:mod:`.errors`) kept in 0x1001 and 0x1003, and each change sent as an EMCY."""

from __future__ import annotations

from hil.drives.definitions import Fault
from hil.protocols.cia402.errors import COMMUNICATION_ERROR, EMCY_NO_ERROR, ErrorRecord
from hil.protocols.cia402.node import STOPPED, DriveNode
from hil.protocols.cia402.objects import DriveObjects
from hil.protocols.cia402.state import EMCY_CODES, ERROR_REGISTER, Cia402StateMachine


class ErrorSignals:
    """One drive's errors as it signals them, over its node as it is now (the drive makes
    a new one with each new node); the caller holds the drive's lock."""

    def __init__(self, errors: ErrorRecord, node: DriveNode, objects: DriveObjects,
                 machine: Cia402StateMachine):
        self.errors = errors
        self._node, self._objects, self._machine = node, objects, machine

    def fault(self, fault: Fault) -> None:
        """A fault of the drive: in force, with its EMCY code and error register bits."""
        code = EMCY_CODES[fault]
        self.errors.enter(code, ERROR_REGISTER[fault])
        self.changed(code)

    def frame_error(self, code: int, data: bytes = b"") -> None:
        """A frame the drive could not take: recorded and signalled (errors' module doc),
        except in STOPPED, where no EMCY goes out (CiA 301) and so none is recorded."""
        if self._node.nmt.state == STOPPED:
            return
        self.errors.enter(code, COMMUNICATION_ERROR)
        self.changed(code, data)

    def end(self, codes) -> None:
        """The errors ``codes`` are over (a frame of their kind came right): those in force
        end, and an EMCY 0x0000 says so."""
        if self.errors.end(codes):
            self.changed(EMCY_NO_ERROR)

    def settle(self, faulted: bool, enabled: bool) -> None:
        """The drive's errors in force end once they are over (ErrorRecord.over)."""
        if self.errors.over(faulted, enabled):
            self.errors.end_drive_errors()
            self.changed(EMCY_NO_ERROR)

    def changed(self, code: int, data: bytes = b"") -> None:
        """0x1001 and 0x1003 as the error record has them, and the EMCY that says so."""
        register = self.errors.register
        self._machine.error_register = register
        self._objects.store_errors()
        self._node.emcy.send(code, register, data)
