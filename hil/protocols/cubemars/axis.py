"""The master's side of a CubeMars AK actuator (the protocol: :mod:`hil.protocols.cubemars`):
MIT mode on firmware V2, driven as any MIT motor (:class:`~hil.protocols.mit.axis.MitAxis`:
enable at standstill, one command per cycle, hold while stopping), its 8-byte answers read
with their error code: an error the motor reports is a fault, cleared by leaving and
entering motor mode on a reset (the manual has no clear-error frame).
"""

from __future__ import annotations

from hil.bus_config.types import DriveConfig
from hil.errors import HilError
from hil.hardware.axis import AxisFault, FaultKind
from hil.protocols.cubemars import CubeMars, CubeMarsOptions, ErrorCode, unpack_mit_answer
from hil.protocols.mit import EXIT_MOTOR_MODE, MitRanges
from hil.protocols.mit.axis import MitAxis


class CubeMarsAxis(MitAxis):
    protocol = CubeMars

    def __init__(self, config: DriveConfig, bus_name: str, on_feedback=lambda: None):
        super().__init__(config, bus_name, on_feedback)
        self.reported = ErrorCode.NONE

    @staticmethod
    def command_settings(config: DriveConfig) -> tuple[MitRanges, float, float, int]:
        options: CubeMarsOptions = config.options or CubeMarsOptions()
        if not options.mit_on_standard_id or not options.kp > 0:
            raise HilError.single(
                f"drive node {config.node_id} ({', '.join(config.joints)}): hil's master "
                "drives CubeMars motors in MIT mode on firmware V2 with its own gains",
                hint="give the drive 'options: {control: mit, firmware: v2, kp: ..., kd: ...}' "
                     "(hil init writes them)")
        return options.ranges(), options.kp, options.kd, options.reply_id

    def _on_reply(self, can_id, data, timestamp) -> None:
        data = bytes(data)
        if len(data) != 8 or data[0] != self.node_id:
            return
        try:
            answer = unpack_mit_answer(data, self.ranges)
        except ValueError:
            return                       # an error code the manual does not define
        self.reported = answer.error
        self.feedback.position, self.feedback.velocity = answer.position, answer.velocity
        self.feedback.torque = answer.torque
        self.booted.set()
        self.answered()

    def fault(self, stopping: bool = False) -> AxisFault | None:
        if self.reported is not ErrorCode.NONE:
            return self.found(FaultKind.FAULT, f"reports {self.reported.name.replace('_', ' ')}",
                              int(self.reported))
        return None

    def forget_faults(self) -> None:
        super().forget_faults()
        self.motor_mode = False
        self.reported = ErrorCode.NONE
        self._pending_special = EXIT_MOTOR_MODE     # then enabled again at standstill
