"""The master's side of a MyActuator RMD motor (the protocol: :mod:`hil.protocols.myactuator`).

hil's master drives the motion mode (protocol V4.2 §5): one command a cycle on ``0x400 +
id`` with the options' gains, answered on ``0x500 + id`` with a 16-bit position. Until it
runs it reads, one frame a cycle, status 1 (the error flags, §2.14), the multi-turn angle
(0.01°, §2.12) and status 2 (the speed, §2.15), and starts at standstill holding where the
motor is. While running it reads status 1 every ERROR_POLL cycles in place of a command
(the motion mode's reply carries no error; the motor keeps the last command meanwhile).
An error is a fault; a fault reset sends the system reset (0x76), the only way V4.2 gives
to clear a level-1 error (§8.2); disabling sends the shutdown (0x80).
"""

from __future__ import annotations

from hil.bus_config.types import DriveConfig
from hil.can.frame import Frame
from hil.can.router import Subscription
from hil.hardware.axis import Axis, AxisCommand, AxisFault, FaultKind
from hil.protocols.mit import pack_command_values
from hil.protocols.mit.axis import MitAxis
from hil.protocols.myactuator import MyActuator, MyActuatorOptions, command_id, reply_id
from hil.protocols.myactuator.codec import (
    MIT_BASE, MIT_RANGES, MIT_REPLY_BASE, Command, ErrorState, unpack_mit_reply,
    unpack_state, unpack_status_1, value_of,
)

#: a running motor's status 1 is read once in this many cycles (hil's choice: 0.2 s at 500 Hz)
ERROR_POLL = 100
#: what a motor that does not run is asked, in turn
_READS = (Command.READ_STATUS_1, Command.READ_MULTI_TURN_ANGLE, Command.READ_STATUS_2)
_DEGREE = 3.141592653589793 / 180


def _request(node_id: int, command: Command) -> Frame:
    return Frame(command_id(node_id), bytes([command]) + bytes(7))


class MyActuatorAxis(Axis):
    protocol = MyActuator

    def __init__(self, config: DriveConfig, bus_name: str, on_feedback=lambda: None):
        super().__init__(config, bus_name, on_feedback)
        options: MyActuatorOptions = config.options or MyActuatorOptions()
        MitAxis.require(config, options.kp > 0, "MyActuator RMD motors in motion mode",
                        f"model: {options.model.name}")
        self.kp, self.kd = options.kp, options.kd
        self.running = False
        self.reported = ErrorState(0)
        self._hold: float | None = None
        self._turn = 0
        self._reset_next = False

    def subscriptions(self) -> list[Subscription]:
        return [Subscription(MIT_REPLY_BASE + self.node_id, self._on_motion),
                Subscription(reply_id(self.node_id), self._on_reply)]

    def _on_motion(self, frame: Frame) -> None:
        if len(frame.data) != 8 or frame.data[0] != self.node_id:
            return
        _, position, velocity, torque = unpack_mit_reply(frame.data)
        feedback = self.feedback
        feedback.position, feedback.velocity, feedback.torque = position, velocity, torque
        self.booted.set()
        self.answered()

    def _on_reply(self, frame: Frame) -> None:
        data = frame.data
        if len(data) != 8:
            return
        if data[0] == Command.READ_STATUS_1:
            self.reported = unpack_status_1(data)[3]
        elif data[0] == Command.READ_MULTI_TURN_ANGLE:
            self.feedback.position = value_of(data) / 100 * _DEGREE
        elif data[0] == Command.READ_STATUS_2:
            state = unpack_state(data)
            self.feedback.velocity = state.speed * _DEGREE
        else:
            return
        self.booted.set()
        self.answered()

    def reset(self) -> None:
        super().reset()
        self.running = False
        self._turn = 0

    @property
    def state(self) -> str:
        if self.reported:
            return str(self.reported.name or int(self.reported))
        return "RUNNING" if self.running else "OFF"

    @property
    def enabled(self) -> bool:
        return self.running

    def cycle_frames(self, command: AxisCommand) -> list[Frame]:
        self._turn += 1
        if self._reset_next:
            self._reset_next = False
            return [_request(self.node_id, Command.RESET)]
        if not self.running:
            if not self.reported and not command.stopping and self.at_standstill() and (
                    self._turn > len(_READS)):
                self.running = True
                self._hold = self.feedback.position
            else:
                return [_request(self.node_id, _READS[self._turn % len(_READS)])]
        if self._turn % ERROR_POLL == 0:
            return [_request(self.node_id, Command.READ_STATUS_1)]
        if command.stopping or command.holding:
            if self._hold is None:
                self._hold = self.feedback.position
            data = pack_command_values(self._hold, 0.0, self.kp, self.kd,
                                       0.0 if command.stopping else command.torque, MIT_RANGES)
        else:
            self._hold = None
            data = pack_command_values(command.target, command.velocity, self.kp, self.kd,
                                       command.torque, MIT_RANGES)
        return [Frame(MIT_BASE + self.node_id, data)]

    def disable_rounds(self) -> list[list[Frame]]:
        self.running = False
        return [[_request(self.node_id, Command.SHUTDOWN)]]

    def fault(self, stopping: bool = False) -> AxisFault | None:
        if self.reported:
            names = " ".join(flag.name or "" for flag in ErrorState if flag in self.reported)
            return self.found(FaultKind.FAULT, f"reports {names}", int(self.reported))
        return None

    def forget_faults(self) -> None:
        """The system reset (0x76) on the next cycle clears the error (§2.25, §8.2)."""
        self.reported = ErrorState(0)
        self.running = False
        self._hold = None
        self._reset_next = True

    @property
    def silence_limit(self) -> float:
        return max(3 * self.config.heartbeat_period, 0.05)

