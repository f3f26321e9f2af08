"""A simulated MIT-protocol motor (the protocol: :mod:`hil.protocols.mit`).

Its CAN timeout follows Ben Katz's mini-cheetah firmware (Hobbyking_Cheetah_Compact,
main.cpp): every frame to the motor, enter-motor-mode included, zeroes the timeout counter
(``onMsgReceived``), which counts only in motor mode; when it expires the firmware zeroes
kp, kd and the feed-forward and stays in motor mode, so the next command drives again
(``timeout_reaction: rest`` leaves motor mode instead, as some forks do).
"""

from __future__ import annotations

from contextlib import AbstractContextManager

from hil.drives.core import DriveCore
from hil.drives.definitions import Fault, Mode, Power, SilenceReaction
from hil.drives.profile import DriveProfile, Reading
from hil.protocols.mit import (
    ENTER_MOTOR_MODE, EXIT_MOTOR_MODE, SET_ZERO, Mit, MitCommand, MitOptions, MitReply,
    TimeoutReaction, pack_reply, unpack_command, unpack_reply,
)


def enter_motor_mode(core: DriveCore) -> None:
    """Motor mode on, with zero gains until the first command (an MIT motor's firmware
    holds no position of its own)."""
    core.enable()
    core.new_setpoint(position=core.status().position, velocity=0.0, torque=0.0,
                      stiffness=0.0, damping=0.0)


def follow(core: DriveCore, command: MitCommand, zero: float) -> None:
    """An MIT command: ``t = kp (p - q) + kd (v - q') + t_ff``, its position from the motor's
    zero."""
    core.new_setpoint(position=command.position + zero, velocity=command.velocity,
                      torque=command.torque, stiffness=command.kp, damping=command.kd)


def zero_commands(core: DriveCore) -> None:
    """The firmware's reaction to its CAN timeout: kp, kd and the feed-forward torque zeroed
    (no torque), motor mode kept."""
    core.new_setpoint(torque=0.0, stiffness=0.0, damping=0.0)


class MitDrive(DriveProfile):
    """A quasi-direct-drive motor speaking the MIT protocol, around a DriveCore."""

    protocol = Mit

    def __init__(self, node_id: int, core: DriveCore, lock: AbstractContextManager,
                 rated_torque: float, heartbeat_period: float = 0.1,
                 options: MitOptions | None = None):
        super().__init__(node_id, core, lock)
        self.options = options or MitOptions()
        self.ranges = self.options.ranges
        self._zero = 0.0             # motor position at "set zero"
        self._reply = b""
        core.set_mode(Mode.IMPEDANCE)
        # the core reports the silence; the reaction is the firmware's (after_update)
        core.silence_reaction = (SilenceReaction.DISABLE if self.options.timeout_reaction
                                 is TimeoutReaction.REST else SilenceReaction.NONE)

    def subscriptions(self):
        return {self.node_id: self._on_frame}

    def _on_frame(self, can_id: int, data: bytes, timestamp: float) -> None:
        if len(data) != 8:
            self.malformed += 1          # the firmware ignores frames that are not 8 bytes
            return
        with self.lock:
            data = bytes(data)
            self.heard()                 # every frame to the motor zeroes its timeout counter
            if data == ENTER_MOTOR_MODE:
                enter_motor_mode(self.core)
            elif data == EXIT_MOTOR_MODE:
                self.core.disable()
            elif data == SET_ZERO:
                self._zero = self.core.status().position
            elif self.core.power is Power.ENABLED:
                follow(self.core, unpack_command(data, self.ranges), self._zero)
            status = self.core.status()
            self._reply = pack_reply(MitReply(self.node_id, status.position - self._zero,
                                              status.velocity, status.torque), self.ranges)
            self.on_command(self)

    def take_replies(self) -> list[tuple[int, bytes]]:
        reply, self._reply = self._reply, b""
        return [(self.options.reply_id, reply)] if reply else []

    def after_update(self) -> None:
        events = self.take_events()
        if Fault.CONTROLLER_SILENT in events and self.core.power is Power.ENABLED:
            zero_commands(self.core)     # the firmware reports nothing

    def readings(self, can_id: int, data: bytes) -> tuple[Reading, ...] | None:
        """A reply: the motor id exact, position (rad from the zero), velocity, torque."""
        if can_id != self.options.reply_id or len(data) != 6:
            return None
        reply = unpack_reply(data, self.ranges)
        return (Reading("motor id", reply.motor_id),
                Reading("position", reply.position, "position"),
                Reading("velocity", reply.velocity, "velocity"),
                Reading("torque", reply.torque, "torque"))

    @property
    def state_text(self) -> str:
        if self.core.power is Power.FAULT:
            return f"FAULT ({self.core.fault.text})"
        return "MOTOR MODE" if self.core.power is Power.ENABLED else "REST MODE"
