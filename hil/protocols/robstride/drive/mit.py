"""A Robstride motor in its MIT protocol mode (RS00 manual 260112, MIT chapter; the maker's
SampleProgram ``RobStride_Motor_MIT_*``): 11-bit ids ``mode << 8 | id``.

Mode 0 carries the special frames, told apart by bytes 6 and 7 after FF x 6 (§8's table):
enable (FF FC) and set run mode (0-2 FC), stop (FF FD) and switch protocol (0-2 FD), set
zero (FF FE), clear fault (FF FB) or read it (other FB), set the motor id (id FA), set the
host id (FD id); any other 8 bytes are the MIT command (§5.5), followed in MIT run mode
only. Mode 1 is position control (float position, float speed: CSP), mode 2 speed control
(float speed, float current limit), each in its run mode only (hil's reading of §6's flows:
set the mode, enable, then send its command). Every frame is answered: answer 1 (§5.1) on
the host's id naming the motor in byte 0, the fault read with the fault answer (§5.7), set
id and switch protocol with answer 2, the MCU id on the motor's id (§5.2).
"""

from __future__ import annotations

import struct
from typing import TYPE_CHECKING

from hil.can.frame import Frame, frame_of_fields
from hil.protocols.mit import unpack_command_values
from hil.protocols.mit.drive import follow
from hil.protocols.mit.codec import MitRanges
from hil.protocols.robstride import Robstride, framing_of
from hil.protocols.robstride import params as P
from hil.protocols.robstride.codec import (
    SET_HOST_MARK, SPECIAL_HEAD, MitSpecial, RunMode, pack_mit_answer, pack_mit_fault,
)

if TYPE_CHECKING:
    from hil.protocols.robstride.drive import RobstrideDrive

#: byte 6 of enable, stop, set zero and clear fault
ALL = 0xFF
#: the MIT run modes (command 6's byte 6) as the private run_mode they run as
RUN_MODES = {0: RunMode.OPERATION, 1: RunMode.POSITION_CSP, 2: RunMode.SPEED}
_FLOATS = struct.Struct("<ff")
#: commands 10 and 11 by id mode: the run mode they act in, the parameters their floats
#: set (the limit, then the reference: §5.12 position and speed, §5.13 speed and current)
FLOAT_COMMANDS = {1: (RunMode.POSITION_CSP, P.LIMIT_SPD, P.LOC_REF),
                  2: (RunMode.SPEED, P.LIMIT_CUR, P.SPD_REF)}


class MitMode:
    """The MIT protocol mode's frames, handled for one drive."""

    def __init__(self, drive: RobstrideDrive):
        self.drive = drive

    def on_frame(self, frame: Frame) -> None:
        drive = self.drive
        if len(frame.data) != 8:
            drive.malformed += 1
            return
        with drive.lock:
            drive.heard()
            drive.answer_with(self.apply(frame.identifier >> 8, bytes(frame.data)))

    def apply(self, mode: int, data: bytes) -> Frame:
        drive = self.drive
        enabled = drive.enabled
        if mode in FLOAT_COMMANDS:
            run_mode, limit, reference = FLOAT_COMMANDS[mode]
            if enabled and drive.run_mode == run_mode:
                target, bound = _FLOATS.unpack(data)
                drive.write_value(limit, abs(bound))
                drive.write_value(reference, target)
            return self.answer()
        if data[:6] == SPECIAL_HEAD:
            special = self.special(data[6], data[7])
            if special is not None:
                return special
        if enabled and drive.run_mode == RunMode.OPERATION:
            follow(drive.core, unpack_command_values(data, self.ranges()), drive.zero)
        return self.answer()

    def special(self, b6: int, b7: int) -> Frame | None:
        """A special frame's effect and answer; None: no special frame (a command)."""
        drive = self.drive
        if b6 == SET_HOST_MARK and b7 not in tuple(MitSpecial):
            drive.host = b7                                  # command 9
            return self.mcu_answer()
        if b7 == MitSpecial.ENABLE_OR_RUN_MODE and (b6 == ALL or b6 in RUN_MODES):
            if b6 == ALL:
                drive.enable()                               # command 1
            else:
                drive.write_value(P.RUN_MODE, RUN_MODES[b6])  # command 6
            return self.answer()
        if b7 == MitSpecial.STOP_OR_PROTOCOL and (b6 == ALL or b6 in (0, 1, 2)):
            if b6 == ALL:
                drive.core.disable()                         # command 2
                return self.answer()
            drive.next_framing = framing_of(b6)              # command 8: at the next boot
            return self.mcu_answer()
        if b7 == MitSpecial.SET_ZERO and b6 == ALL:
            drive.set_zero()                                 # command 4
            return self.answer()
        if b7 == MitSpecial.CLEAR_OR_READ_FAULT:
            if b6 == ALL:                                    # command 5
                drive.clear_faults()
                return self.answer()
            return self._host_frame(pack_mit_fault(drive.node_id, drive.fault_word()))
        if b7 == MitSpecial.SET_ID and b6 in Robstride.node_ids:
            drive.set_motor_id(b6)                           # command 7
            return self.mcu_answer()
        return None

    def ranges(self) -> MitRanges:
        ranges = self.drive.ranges
        return MitRanges(ranges.p_max, ranges.v_max, ranges.kp_max, ranges.kd_max,
                         ranges.t_max)

    def answer(self) -> Frame:
        """Answer 1 on the host's id (mode 0)."""
        drive = self.drive
        return self._host_frame(pack_mit_answer(drive.reported(), drive.ranges))

    def _host_frame(self, data: bytes) -> Frame:
        return frame_of_fields((self.drive.host, data, False, False, False, False, False, 0.0))

    def mcu_answer(self) -> Frame:
        """Answer 2 (§5.2): the 64-bit MCU id on the motor's own id."""
        drive = self.drive
        return frame_of_fields((drive.node_id, drive.mcu_id(), False, False, False, False,
                                False, 0.0))
