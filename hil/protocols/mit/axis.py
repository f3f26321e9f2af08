"""The master's side of a MIT-protocol motor (the protocol: :mod:`hil.protocols.mit`).

Exactly one frame per motor per cycle, always answered: the enter/exit
motor-mode special frames when the mode changes, otherwise a command. In
rest mode the command carries zero gains (its answer is the feedback);
stopping holds the motor where it is with the configured gains. The protocol
reports no state and no faults: the mode is what the master last commanded,
and a motor that stops answering is found silent.
"""

from __future__ import annotations

from hil.bus_config.types import DriveConfig
from hil.hardware.axis import Axis, AxisCommand, Frame
from hil.protocols.mit import (
    ENTER_MOTOR_MODE, EXIT_MOTOR_MODE, Mit, MitCommand, MitOptions, MitRanges, pack_command,
    unpack_reply,
)


class MitAxis(Axis):
    protocol = Mit

    def __init__(self, config: DriveConfig, bus_name: str, on_feedback=lambda: None):
        super().__init__(config, bus_name, on_feedback)
        self.ranges, self.kp, self.kd, self.reply_id = self.command_settings(config)
        self.motor_mode = False
        self._pending_special: bytes | None = None
        self._hold: float | None = None

    @staticmethod
    def command_settings(config: DriveConfig) -> tuple[MitRanges, float, float, int]:
        """The commands' ranges, the master's gains and the id the motor answers on."""
        options: MitOptions = config.options          # kp > 0: checked with the bus config
        return options.ranges, options.kp, options.kd, options.reply_id

    def subscriptions(self):
        # every motor answers on the master's id; each axis keeps the answers with its id
        return {self.reply_id: self._on_reply}

    def _on_reply(self, can_id, data, timestamp) -> None:
        if len(data) != 6 or data[0] != self.node_id:
            return
        reply = unpack_reply(bytes(data), self.ranges)
        self.feedback.position, self.feedback.velocity = reply.position, reply.velocity
        self.feedback.torque = reply.torque
        self.booted.set()
        self.answered()

    def reset(self) -> None:
        """Rest mode first: the next cycle's frame is EXIT MOTOR MODE."""
        super().reset()
        self._pending_special = EXIT_MOTOR_MODE
        self.motor_mode = False

    @property
    def state(self) -> str:
        return "MOTOR MODE" if self.motor_mode else "REST MODE"

    @property
    def enabled(self) -> bool:
        return self.motor_mode

    def cycle_frames(self, command: AxisCommand) -> list[Frame]:
        target, velocity, torque = command.target, command.velocity, command.torque
        stopping, enabling = command.stopping, command.holding
        if self._pending_special is not None:
            special, self._pending_special = self._pending_special, None
            return [(self.node_id, special, False)]
        if not self.motor_mode and not stopping and self.at_standstill():
            self.motor_mode = True
            self._hold = self.feedback.position
            return [(self.node_id, ENTER_MOTOR_MODE, False)]
        if not self.motor_mode:
            sent = MitCommand(self.feedback.position, 0.0, 0.0, 0.0, 0.0)
        elif stopping or enabling:
            if self._hold is None:
                self._hold = self.feedback.position
            sent = MitCommand(self._hold, 0.0, self.kp, self.kd, 0.0 if stopping else torque)
        else:
            self._hold = None
            sent = MitCommand(target, velocity, self.kp, self.kd, torque)
        return [(self.node_id, pack_command(sent, self.ranges), False)]

    def disable_rounds(self) -> list[list[Frame]]:
        self.motor_mode = False
        return [[(self.node_id, EXIT_MOTOR_MODE, False)]]

    def forget_faults(self) -> None:
        self._hold = None

    @property
    def silence_limit(self) -> float:
        return max(3 * self.config.heartbeat_period, 0.05)
