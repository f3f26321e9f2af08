"""The master's side of a CubeMars AK actuator (the protocol: :mod:`hil.protocols.cubemars`):
MIT mode on firmware V2, driven as any MIT motor (:class:`~hil.protocols.mit.axis.MitAxis`:
enable at standstill, one command per cycle, hold while stopping), its 8-byte answers read
with their error code: an error the motor reports is a fault, cleared by leaving and
entering motor mode on a reset (the manual has no clear-error frame).
"""

from __future__ import annotations

from hil.bus_config.types import DriveConfig
from hil.hardware.axis import AxisFault, FaultKind
from hil.protocols.cubemars import CubeMars, CubeMarsOptions, ErrorCode, unpack_mit_answer
from hil.protocols.mit import EXIT_MOTOR_MODE, MitRanges
from hil.protocols.mit.axis import MitAxis, MotorAnswers


class CubeMarsAnswers(MotorAnswers):
    """An AK motor's V2 MIT answer on the reply id: 8 bytes naming the driver in byte 0,
    its error code last (§5.3)."""

    NOTHING = ErrorCode.NONE

    def read(self, data: bytes) -> tuple[float, float, float] | None:
        if len(data) != 8 or data[0] != self.node_id:
            return None
        try:
            answer = unpack_mit_answer(data, self.ranges)
        except ValueError:
            return None                  # an error code the manual does not define
        self.reported = answer.error
        return answer.position, answer.velocity, answer.torque


class CubeMarsAxis(MitAxis):
    protocol = CubeMars
    Answers = CubeMarsAnswers

    def command_settings(self, config: DriveConfig) -> tuple[MitRanges, float, float, int]:
        options: CubeMarsOptions = config.options or CubeMarsOptions()
        MitAxis.require(config, options.mit_on_standard_id and options.kp > 0,
                        "CubeMars motors in MIT mode on firmware V2", "control: mit, firmware: v2")
        return options.ranges(), options.kp, options.kd, options.reply_id

    def fault(self, stopping: bool = False) -> AxisFault | None:
        reported = self.answers.reported
        if reported is not ErrorCode.NONE:
            return self.found(FaultKind.FAULT, f"reports {reported.name.replace('_', ' ')}",
                              int(reported))
        return None

    def forget_faults(self) -> None:
        super().forget_faults()
        self.motor_mode = False
        # the manual has no clear-error frame: leaving motor mode, then entering it again at
        # standstill, clears the error (the module doc)
        self.answers.forget()
        self.specials.send_next(EXIT_MOTOR_MODE)
