"""The master's side of a MIT-protocol motor (the protocol: :mod:`hil.protocols.mit`), and of
every motor of its family (Damiao's and CubeMars' axes are this one with their answers).

Exactly one frame per motor per cycle, always answered: the enter/exit
motor-mode special frames when the mode changes, otherwise a command. In
rest mode the command carries zero gains (its answer is the feedback);
stopping holds the motor where it is with the configured gains. The protocol
reports no state and no faults: the mode is what the master last commanded,
and a motor that stops answering is found silent.

What a family changes is in two objects the axis owns: its :class:`MotorAnswers` (which
frames on the master's id are its motor's answers, what they carry) and the special frame
its next cycle sends instead of a command (:class:`SpecialFrames`).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import ClassVar

from mypy_extensions import mypyc_attr

from hil.bus_config.types import DriveConfig
from hil.can.frame import Frame
from hil.can.router import Subscription
from hil.errors import ConfigError
from hil.hardware.axis import Axis, AxisCommand
from hil.protocols.mit import (
    ENTER_MOTOR_MODE, EXIT_MOTOR_MODE, Mit, MitOptions, MitRanges, frame_on_bus,
    pack_command_values, unpack_motion,
)


class SpecialFrames:
    """The special frame an axis sends in place of its next cycle's command (exit motor
    mode on a reset, a family's clear-error): one deep, a later one replacing an earlier,
    as the master sends one frame a motor a cycle."""

    __slots__ = ("next",)

    def __init__(self) -> None:
        #: the data of the frame the next cycle sends (None: a command)
        self.next: bytes | None = None

    def send_next(self, data: bytes) -> None:
        self.next = data

    def take(self) -> bytes | None:
        """The frame's data, now sent (None: none was waiting)."""
        data, self.next = self.next, None
        return data


@mypyc_attr(allow_interpreted_subclasses=True)     # CubeMars' answers (not compiled)
class MotorAnswers:
    """Which frames on the master's id are one motor's answers, and what each carries: a
    MIT motor's, 6 bytes naming it in byte 0 (Hobbyking_Cheetah_Compact CAN_com.cpp,
    ``pack_reply``). A family whose answers say more subclasses it, keeping what they report
    beside the motion in :attr:`reported`."""

    #: what a motor has reported before its first answer, and after :meth:`forget`
    NOTHING: ClassVar[object] = None

    def __init__(self, node_id: int, ranges: MitRanges):
        self.node_id = node_id
        self.ranges = ranges
        #: what the last answer reported beside the motion (a family's state or error)
        self.reported = self.NOTHING

    def read(self, data: bytes) -> tuple[float, float, float] | None:
        """The motion (position, velocity, torque) that ``data`` answers if it is this
        motor's answer, else None: a plain tuple, as every family's answer carries it in
        bytes 1-5 (no named tuple made a motor a cycle)."""
        if len(data) != 6 or data[0] != self.node_id:
            return None
        return unpack_motion(data, self.ranges)

    def forget(self) -> None:
        """Before a fault reset: what the motor reported is forgotten until it answers."""
        self.reported = self.NOTHING


@mypyc_attr(allow_interpreted_subclasses=True)     # CubeMars' axis (not compiled)
class MitAxis(Axis):
    protocol = Mit
    #: the answers of this family's motors
    Answers: ClassVar[type[MotorAnswers]] = MotorAnswers

    def __init__(self, config: DriveConfig, bus_name: str, on_feedback=lambda: None):
        super().__init__(config, bus_name, on_feedback)
        self.ranges, self.kp, self.kd, self.reply_id = self.command_settings(config)
        self.answers = self.Answers(config.node_id, self.ranges)
        self.specials = SpecialFrames()
        self.motor_mode = False
        self._hold: float | None = None
        #: a frame of the master's to this motor, of its data (its id and format on the bus:
        #: :meth:`frame_maker`)
        self.to_motor = self.frame_maker(config)

    # frame_maker and command_settings are methods, not static ones: compiled (mypyc), a
    # static method called on self is the class' own, never an interpreted subclass' override
    def frame_maker(self, config: DriveConfig) -> Callable[[bytes], Frame]:
        """How the master's frames to the motor of ``config`` are made of their data: a
        classic frame on its node id (a family whose frames differ on some bus says how)."""
        return functools.partial(frame_on_bus, config.node_id, fd=False)

    def command_settings(self, config: DriveConfig) -> tuple[MitRanges, float, float, int]:
        """The commands' ranges, the master's gains and the id the motor answers on."""
        options: MitOptions = config.options          # kp > 0: checked with the bus config
        return options.ranges, options.kp, options.kd, options.reply_id

    @staticmethod
    def require(config: DriveConfig, met: bool, how: str, options: str) -> None:
        """A ConfigError unless ``met``: hil's master drives the family's motors ``how``
        with its own gains, which the drive's ``options`` give."""
        if not met:
            raise ConfigError.single(
                f"drive node {config.node_id} ({', '.join(config.joints)}): hil's master "
                f"drives {how} with its own gains",
                hint=f"give the drive 'options: {{{options}, kp: ..., kd: ...}}' (hil init "
                     "writes them)")

    def subscriptions(self) -> list[Subscription]:
        # every motor answers on the master's id; each axis keeps the answers with its id
        return [Subscription(self.reply_id, self._on_reply)]

    def _on_reply(self, frame: Frame) -> None:
        motion = self.answers.read(frame.data)
        if motion is None:
            return
        feedback = self.feedback
        feedback.position, feedback.velocity, feedback.torque = motion
        self.booted.set()
        self.answered()

    def reset(self) -> None:
        """Rest mode first: the next cycle's frame is EXIT MOTOR MODE."""
        super().reset()
        self.specials.send_next(EXIT_MOTOR_MODE)
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
        special = self.specials.take()
        if special is not None:
            return [self.to_motor(special)]
        if not self.motor_mode and not stopping and self.at_standstill():
            self.motor_mode = True
            self._hold = self.feedback.position
            return [self.to_motor(ENTER_MOTOR_MODE)]
        if not self.motor_mode:
            data = pack_command_values(self.feedback.position, 0.0, 0.0, 0.0, 0.0, self.ranges)
        elif stopping or enabling:
            if self._hold is None:
                self._hold = self.feedback.position
            data = pack_command_values(self._hold, 0.0, self.kp, self.kd,
                                       0.0 if stopping else torque, self.ranges)
        else:
            self._hold = None
            data = pack_command_values(target, velocity, self.kp, self.kd, torque, self.ranges)
        return [self.to_motor(data)]

    def disable_rounds(self) -> list[list[Frame]]:
        self.motor_mode = False
        return [[self.to_motor(EXIT_MOTOR_MODE)]]

    def forget_faults(self) -> None:
        self._hold = None

    @property
    def silence_limit(self) -> float:
        return max(3 * self.config.heartbeat_period, 0.05)
