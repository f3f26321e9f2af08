"""The master's side of a Damiao DM-J motor (the protocol: :mod:`hil.protocols.damiao`):
MIT commands, as a MIT-protocol motor takes them (:class:`~hil.protocols.mit.axis.MitAxis`:
enable at standstill, one command per cycle, hold while stopping), and the motor's 8-byte
feedback, whose state nibble the master watches: an error the motor reports (lost
communication, overload, ...) is a fault, cleared with the clear-error frame on a reset.
On a CAN FD bus every frame goes as an FD frame with the bit-rate switch, as openarm_can
sends them (:func:`hil.protocols.mit.codec.frame_on_bus`).
"""

from __future__ import annotations

import functools
from collections.abc import Callable

from hil.bus_config.types import DriveConfig
from hil.can.frame import Frame
from hil.hardware.axis import AxisFault, FaultKind
from hil.protocols.damiao import (
    CLEAR_ERROR, ERROR_STATES, STATE_TEXT, STATES, ControlMode, Damiao, DamiaoOptions, State,
    is_register_answer,
)
from hil.protocols.mit import MitRanges, frame_on_bus, unpack_motion
from hil.protocols.mit.axis import MitAxis, MotorAnswers


class DamiaoAnswers(MotorAnswers):
    """A DM-J motor's feedback on the master's id: 8 bytes, the motor's id in the low nibble
    of D0 and its state in the high one; a register answer shares the id (told apart as the
    maker's sample code tells it: :func:`~hil.protocols.damiao.is_register_answer`)."""

    NOTHING = State.DISABLED

    def read(self, data: bytes) -> tuple[float, float, float] | None:
        if (len(data) != 8 or is_register_answer(data)
                or (data[0] & 0x0F) != (self.node_id & 0x0F)):
            return None
        state = STATES.get(data[0] >> 4)     # D0's high nibble (unpack_feedback's reading)
        if state is None:
            return None                  # a state code the maker does not define
        self.reported = state
        return unpack_motion(data, self.ranges)


class DamiaoAxis(MitAxis):
    protocol = Damiao
    Answers = DamiaoAnswers

    def command_settings(self, config: DriveConfig) -> tuple[MitRanges, float, float, int]:
        options: DamiaoOptions = config.options or DamiaoOptions()
        MitAxis.require(config, options.control_mode is ControlMode.MIT and options.kp > 0,
                        "Damiao motors in MIT mode", "control_mode: MIT")
        return options.ranges(), options.kp, options.kd, options.reply_id(config.node_id)

    def frame_maker(self, config: DriveConfig) -> Callable[[bytes], Frame]:
        """On a CAN FD bus an FD frame with the bit-rate switch (:func:`frame_on_bus`)."""
        if config.can_fd:
            return functools.partial(frame_on_bus, config.node_id, fd=True)
        return super().frame_maker(config)

    @property
    def state(self) -> str:
        return STATE_TEXT[self.answers.reported]

    @property
    def enabled(self) -> bool:
        return self.motor_mode and self.answers.reported is State.ENABLED

    def fault(self, stopping: bool = False) -> AxisFault | None:
        if self.answers.reported in ERROR_STATES:
            reported: State = self.answers.reported
            return self.found(FaultKind.FAULT, f"reports {self.state}", int(reported))
        return None

    def forget_faults(self) -> None:
        super().forget_faults()
        self.motor_mode = False
        # the maker's clear-error frame (FB; app_commands.c CAN_COMMAND_CLEAR_FAULT), then
        # enabled again at standstill
        self.specials.send_next(CLEAR_ERROR)
