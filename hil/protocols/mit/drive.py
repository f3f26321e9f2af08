"""A simulated MIT-protocol motor (the protocol: :mod:`hil.protocols.mit`).

Its CAN timeout follows Ben Katz's mini-cheetah firmware (Hobbyking_Cheetah_Compact,
main.cpp): every frame to the motor, enter-motor-mode included, zeroes the timeout counter
(``onMsgReceived``), which counts only in motor mode; when it expires the firmware zeroes
kp, kd and the feed-forward and stays in motor mode, so the next command drives again
(``timeout_reaction: rest`` leaves motor mode instead, as some forks do).

What every motor of the family (Damiao's, CubeMars') does alike is :class:`MitFamilyDrive`.
"""

from __future__ import annotations

from abc import abstractmethod
from contextlib import AbstractContextManager

from mypy_extensions import mypyc_attr

from hil.bus_config.types import DriveConfig
from hil.can.frame import Frame, frame_of_fields
from hil.can.router import Subscription
from hil.drives.core import DriveCore
from hil.drives.definitions import Fault, Mode, Power, SilenceReaction
from hil.drives.profile import DriveProfile, Reading
from hil.protocols.mit import (
    ENTER_MOTOR_MODE, EXIT_MOTOR_MODE, SET_ZERO, Mit, MitRanges, TimeoutReaction,
    pack_answer, unpack_command_values, unpack_reply,
)


def enter_motor_mode(core: DriveCore) -> None:
    """Motor mode on, with zero gains until the first command (an MIT motor's firmware
    holds no position of its own)."""
    core.enable()
    core.new_setpoint(position=core.status().position, velocity=0.0, torque=0.0,
                      stiffness=0.0, damping=0.0)


def follow(core: DriveCore, command: tuple[float, float, float, float, float],
           zero: float) -> None:
    """An MIT command (position, velocity, kp, kd, torque: an MitCommand, or the plain tuple
    of :func:`~hil.protocols.mit.unpack_command_values`): ``t = kp (p - q) + kd (v - q') +
    t_ff``, its position from the motor's zero."""
    position, velocity, kp, kd, torque = command
    core.new_setpoint(position=position + zero, velocity=velocity, torque=torque,
                      stiffness=kp, damping=kd)


def zero_commands(core: DriveCore) -> None:
    """The firmware's reaction to its CAN timeout: kp, kd and the feed-forward torque zeroed
    (no torque), motor mode kept."""
    core.new_setpoint(torque=0.0, stiffness=0.0, damping=0.0)


def motion_readings(answer) -> tuple[Reading, Reading, Reading]:
    """The motion an answer of the family carries (bytes 1-5 in every family's:
    :func:`hil.protocols.mit.pack_motion`), for a replay's comparison within tolerances."""
    return (Reading("position", answer.position, "position"),
            Reading("velocity", answer.velocity, "velocity"),
            Reading("torque", answer.torque, "torque"))


@mypyc_attr(allow_interpreted_subclasses=True)     # CubeMars' motor (not compiled)
class MitFamilyDrive(DriveProfile):
    """What a motor of the MIT family does alike, whoever made it: it is built from its
    drive's config with its protocol's options (:attr:`options`); a command frame is 8 bytes
    (another length is malformed, ignored as each firmware ignores it: the mini-cheetah's
    ``onMsgReceived``, Damiao's and CubeMars' 8-byte commands), heard (it restarts the CAN
    timeout whatever it says) and answered once applied (:meth:`apply`: by default as the
    mini-cheetah firmware takes it), its answer taken once."""

    #: the commands' ranges (each family's drive sets them)
    ranges: MitRanges
    #: an MIT command's layout, to the values :func:`follow` takes (CubeMars' firmware V3
    #: has its own)
    decode_command = staticmethod(unpack_command_values)

    def __init__(self, config: DriveConfig, core: DriveCore, lock: AbstractContextManager):
        super().__init__(config, core, lock)
        self.options = config.options or self.protocol.Options()
        #: the motor's position at its zero (set zero, save zero, set origin)
        self.zero = 0.0
        self._reply: Frame | None = None

    def on_frame(self, frame: Frame) -> None:
        """A command frame to the motor (special frames included)."""
        if len(frame.data) != 8:
            frame = self.of_other_length(frame)
            if frame is None:
                return
        with self.lock:
            self.heard()
            self._reply = self.apply(frame)
            self.on_command(self)

    def of_other_length(self, frame: Frame) -> Frame | None:
        """A command frame of other than 8 data bytes as the motor takes it, or None where it
        ignores it: here malformed, counted (a family whose firmware reads such a frame says
        how). Asked only for such a frame: the common one costs no call."""
        self.malformed += 1
        return None

    def apply(self, frame: Frame) -> Frame:
        """What an 8-byte command frame does to the motor (the lock held); its answer. Here
        the mini-cheetah firmware's (main.cpp ``onMsgReceived``): enter motor mode, exit it,
        set the zero here, else a command, followed in motor mode only (answered all the
        same)."""
        data = frame.data
        if data == ENTER_MOTOR_MODE:
            self.enter()
        elif data == EXIT_MOTOR_MODE:
            self.core.disable()
        elif data == SET_ZERO:
            self.zero = self.core.status().position
        elif self.core.power is Power.ENABLED:
            follow(self.core, self.decode_command(data, self.ranges), self.zero)
        return self.answer()

    def enter(self) -> None:
        """Enter motor mode."""
        enter_motor_mode(self.core)

    @abstractmethod
    def answer(self) -> Frame:
        """The frame that answers a command now (the lock held): a frame every cycle, built
        with :func:`~hil.can.frame.frame_of_fields` (from C) where it is a standard one."""

    def take_replies(self) -> list[Frame]:
        reply, self._reply = self._reply, None
        return [reply] if reply is not None else []

    def mode_text(self) -> str:
        return "MOTOR MODE" if self.core.power is Power.ENABLED else "REST MODE"


class MitDrive(MitFamilyDrive):
    """A quasi-direct-drive motor speaking the MIT protocol, around a DriveCore."""

    protocol = Mit

    def __init__(self, config: DriveConfig, core: DriveCore, lock: AbstractContextManager):
        super().__init__(config, core, lock)
        self.ranges = self.options.ranges
        core.set_mode(Mode.IMPEDANCE)
        # the core reports the silence; the reaction is the firmware's (after_update)
        core.silence_reaction = (SilenceReaction.DISABLE if self.options.timeout_reaction
                                 is TimeoutReaction.REST else SilenceReaction.NONE)

    def subscriptions(self) -> list[Subscription]:
        return [Subscription(self.node_id, self.on_frame)]

    def answer(self) -> Frame:
        status = self.core.status()
        data = pack_answer(self.node_id, status.position - self.zero, status.velocity,
                           status.torque, self.ranges, b"")
        return frame_of_fields((self.options.reply_id, data, False, False, False, False, False,
                                0.0))

    def after_update(self) -> None:
        events = self.take_events()
        if Fault.CONTROLLER_SILENT in events and self.core.power is Power.ENABLED:
            zero_commands(self.core)     # the firmware reports nothing

    def readings(self, frame: Frame) -> tuple[Reading, ...] | None:
        """A reply: the motor id exact, position (rad from the zero), velocity, torque."""
        if frame.identifier != self.options.reply_id or len(frame.data) != 6:
            return None
        reply = unpack_reply(frame.data, self.ranges)
        return (Reading("motor id", reply.motor_id), *motion_readings(reply))

    @property
    def state_text(self) -> str:
        fault = self.core.fault         # set while the power is FAULT
        if self.core.power is Power.FAULT and fault is not None:
            return f"FAULT ({fault.text})"
        return self.mode_text()
