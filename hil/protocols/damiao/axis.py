"""The master's side of a Damiao DM-J motor (the protocol: :mod:`hil.protocols.damiao`):
MIT commands, as a MIT-protocol motor takes them (:class:`~hil.protocols.mit.axis.MitAxis`:
enable at standstill, one command per cycle, hold while stopping), and the motor's 8-byte
feedback, whose state nibble the master watches: an error the motor reports (lost
communication, overload, ...) is a fault, cleared with the clear-error frame on a reset.
"""

from __future__ import annotations

from hil.bus_config.types import DriveConfig
from hil.errors import HilError
from hil.hardware.axis import AxisFault, FaultKind
from hil.protocols.damiao import (
    CLEAR_ERROR, ControlMode, Damiao, DamiaoOptions, State, is_register_answer, unpack_feedback,
)
from hil.protocols.mit import MitRanges
from hil.protocols.mit.axis import MitAxis


class DamiaoAxis(MitAxis):
    protocol = Damiao

    def __init__(self, config: DriveConfig, bus_name: str, on_feedback=lambda: None):
        super().__init__(config, bus_name, on_feedback)
        self.reported = State.DISABLED

    @staticmethod
    def command_settings(config: DriveConfig) -> tuple[MitRanges, float, float, int]:
        options: DamiaoOptions = config.options or DamiaoOptions()
        if options.control_mode is not ControlMode.MIT or not options.kp > 0:
            raise HilError.single(
                f"drive node {config.node_id} ({', '.join(config.joints)}): hil's master "
                "drives Damiao motors in MIT mode with its own gains",
                hint="give the drive 'options: {control_mode: MIT, kp: ..., kd: ...}' (hil "
                     "init writes them)")
        return options.ranges(), options.kp, options.kd, options.reply_id(config.node_id)

    def _on_reply(self, can_id, data, timestamp) -> None:
        data = bytes(data)
        if (len(data) != 8 or is_register_answer(data)
                or (data[0] & 0x0F) != (self.node_id & 0x0F)):
            return
        try:
            feedback = unpack_feedback(data, self.ranges)
        except ValueError:
            return                       # a state code the maker does not define
        self.reported = feedback.state
        self.feedback.position, self.feedback.velocity = feedback.position, feedback.velocity
        self.feedback.torque = feedback.torque
        self.booted.set()
        self.answered()

    @property
    def state(self) -> str:
        return self.reported.name.replace("_", " ")

    @property
    def enabled(self) -> bool:
        return self.motor_mode and self.reported is State.ENABLED

    def fault(self, stopping: bool = False) -> AxisFault | None:
        if self.reported.is_error:
            return self.found(FaultKind.FAULT, f"reports {self.state}", int(self.reported))
        return None

    def forget_faults(self) -> None:
        super().forget_faults()
        self.motor_mode = False
        self._pending_special = CLEAR_ERROR       # then enabled again at standstill
