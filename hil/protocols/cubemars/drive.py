"""A simulated CubeMars AK actuator (the protocol: :mod:`hil.protocols.cubemars`), around a
DriveCore at the output shaft (the built-in gear folded in, as the motor's frames are).

MIT mode: motor mode is entered and left by the special frames; a command moves the motor
only in motor mode; every frame is answered. Servo mode: the manual knows no enable, so
the first command powers the motor in its mode, as the product does; the status is
uploaded at the configured rate whatever the motor does. In both, a silence beyond the bus
config's ``watchdog_timeout`` (by default 0: none) releases the motor (hil's choice: the
manual documents no CAN timeout); every frame to the motor is a sign of life, and the
silence counts only while the motor runs, as the mini-cheetah firmware's timeout counter
that the AK's MIT mode descends from (hil's reading). A fault hil injects (``hil sim
--fault``) is reported with the error code OVER_CURRENT, the manual's nearest (hil's
choice), the motor released, until motor mode is entered again (MIT) or the next command
(servo).
"""

from __future__ import annotations

import math
import struct
from contextlib import AbstractContextManager
from dataclasses import replace

from hil.bus_config.types import DriveConfig
from hil.can.frame import Frame, frame_of_fields
from hil.can.router import Subscription
from hil.drives.core import DriveCore
from hil.drives.definitions import Fault, Mode, Power, SilenceReaction
from hil.drives.profile import Reading
from hil.protocols.cubemars import (
    DEFAULT_ERPM, DEFAULT_ERPM_PER_S, MAX_AMPERES, MAX_ERPM, SPECIAL_FRAMES, Answer, Control,
    CubeMars, CubeMarsOptions, ErrorCode, Firmware, ServoMode, command_id, pack_mit_answer,
    pack_status, status_id, unpack_mit_answer, unpack_v3_command,
)
from hil.protocols.mit.drive import MitFamilyDrive, enter_motor_mode, motion_readings

#: the driver board's temperature (°C): no heating is modelled
AMBIENT = 25
_INT32 = struct.Struct(">i")
_POSITION_SPEED = struct.Struct(">ihh")
#: servo-mode field lengths (bytes) each mode reads
_SERVO_LENGTH = {ServoMode.ORIGIN: 1, ServoMode.POSITION_SPEED: 8}


class CubeMarsDrive(MitFamilyDrive):
    """One AK actuator on a bus."""

    protocol = CubeMars
    options: CubeMarsOptions

    def __init__(self, config: DriveConfig, core: DriveCore, lock: AbstractContextManager):
        super().__init__(config, core, lock)
        self.model = self.options.model
        self.ranges = self.options.ranges()
        if self.options.firmware is Firmware.V3:
            self.decode_command = unpack_v3_command
        self.error = ErrorCode.NONE
        self._peak = core.parameters.peak_torque
        self._next_status = 0.0
        self._servo_mode: ServoMode | None = None      # the last servo-mode command's
        #: servo mode: each command id of the motor (extended), with its mode
        self._servo_modes = {command_id(self.node_id, mode): mode for mode in ServoMode
                             if mode is not ServoMode.MIT}
        # a silence releases the motor (hil's choice, the module doc: the manual has no timeout)
        core.silence_reaction = SilenceReaction.DISABLE

    # --- bus ----------------------------------------------------------------------------

    def subscriptions(self) -> list[Subscription]:
        """Servo mode: the command of each mode on its extended id (§5.1: ``mode << 8 |
        id``), one subscription a mode (a mask on the id's low byte would bring the drive
        every extended frame naming its id, its status uploads and modes it lacks included,
        to sort frame by frame); V3 MIT: the command on the extended id of mode 8, the
        special frames on the extended id ``id``; V2 MIT: the standard id ``id``."""
        if self.options.control is Control.SERVO:
            return [Subscription(identifier, self._on_servo, extended=True)
                    for identifier in self._servo_modes]
        if self.options.firmware is Firmware.V3:
            return [Subscription(command_id(self.node_id, ServoMode.MIT), self.on_frame,
                                 extended=True),
                    Subscription(command_id(self.node_id, ServoMode.DUTY),
                                 self._on_v3_special, extended=True)]
        return [Subscription(self.node_id, self.on_frame)]

    # --- MIT mode --------------------------------------------------------------------------

    def _on_v3_special(self, frame: Frame) -> None:
        """V3: the special frames come on the id ``id`` (mode 0); a duty frame to a motor in
        MIT mode moves nothing and is not answered."""
        if frame.data in SPECIAL_FRAMES:
            self.on_frame(frame)

    def enter(self) -> None:
        """Motor mode entered: a reported error cleared (the module doc), an enabled motor
        left as it is."""
        self.error = ErrorCode.NONE
        if self.core.power is Power.FAULT:
            self.core.reset_fault()
        if self.core.power is not Power.ENABLED:
            self.core.set_mode(Mode.IMPEDANCE)
            enter_motor_mode(self.core)

    def answer(self) -> Frame:
        """V2: the 8-byte MIT answer on the reply id; V3: the status frame."""
        if self.options.firmware is Firmware.V3:
            return Frame(status_id(self.node_id), pack_status(self._reported(), self.model),
                         extended=True)
        data = pack_mit_answer(self._reported(), self.ranges)
        return frame_of_fields((self.options.reply_id, data, False, False, False, False, False,
                                0.0))

    # --- servo mode --------------------------------------------------------------------

    def _on_servo(self, frame: Frame) -> None:
        mode, data = self._servo_modes[frame.identifier], frame.data
        if len(data) < _SERVO_LENGTH.get(mode, 4):
            self.malformed += 1          # too short for the mode's field
            return
        with self.lock:
            self.heard()
            SERVO[mode](self, data)
            self._servo_mode = mode
            self.on_command(self)

    def _powered(self, mode: Mode) -> None:
        """Servo mode: a command powers the motor in the core mode it needs."""
        self.error = ErrorCode.NONE
        if self.core.power is Power.FAULT:
            self.core.reset_fault()
        if self.core.mode is not mode or self.core.power is not Power.ENABLED:
            self.core.set_mode(mode)
            self.core.enable()
            self.core.hold_position()

    def _duty(self, data: bytes) -> None:
        """hil models no PWM: a duty sets the winding voltage, so the unloaded speed follows
        it, duty 1 the model's top speed (hil's choice)."""
        duty = max(-1.0, min(1.0, _INT32.unpack_from(data)[0] / 100000))
        self._speed(duty * (self.model.no_load_speed or self.ranges.v_max))

    def _current(self, data: bytes) -> None:
        self._powered(Mode.TORQUE)
        self._limit_torque(self._peak)
        amperes = _within(_INT32.unpack_from(data)[0] / 1000, MAX_AMPERES)
        self.core.new_setpoint(torque=amperes * self.model.torque_constant)

    def _current_brake(self, data: bytes) -> None:
        """Held where it is with at most the brake current's torque: "the motor is fixed at
        the current position by the specified brake current" (§5.1), so a move or a speed in
        progress is dropped where the brake takes hold, and held there while braking."""
        amperes = min(abs(_INT32.unpack_from(data)[0] / 1000), MAX_AMPERES)
        if self._servo_mode is not ServoMode.CURRENT_BRAKE or (
                self.core.power is not Power.ENABLED):
            self._powered(Mode.PROFILE_POSITION)
            self.core.hold_position()
        self._limit_torque(min(self._peak, amperes * self.model.torque_constant))

    def _erpm(self, data: bytes) -> None:
        self._speed(self.model.output_speed(_within(_INT32.unpack_from(data)[0], MAX_ERPM)))

    def _speed(self, speed: float) -> None:
        self._powered(Mode.PROFILE_VELOCITY)
        # the manual gives the speed loop no ramp: the reference steps (hil's reading)
        self._profile(abs(speed) or 1.0, 1e9)
        self.core.new_setpoint(velocity=speed)

    def _position(self, data: bytes) -> None:
        degrees = _INT32.unpack_from(data)[0] / 10000
        self._move(degrees, DEFAULT_ERPM, DEFAULT_ERPM_PER_S)

    def _position_speed(self, data: bytes) -> None:
        degrees, speed, acceleration = _POSITION_SPEED.unpack_from(data)
        self._move(degrees / 10000, abs(speed) * 10.0, abs(acceleration) * 10.0)

    def _move(self, degrees: float, erpm: float, erpm_per_s: float) -> None:
        self._powered(Mode.PROFILE_POSITION)
        self._profile(self.model.output_speed(min(erpm, MAX_ERPM)),
                      self.model.output_speed(erpm_per_s))
        self.core.move_to(math.radians(degrees) + self.zero)

    def _origin(self, data: bytes) -> None:
        """0 a temporary, 1 a permanent origin here; 2 the default origin back (§5.1.6).
        Nothing moves."""
        if data[0] in (0, 1):
            self.zero = self.core.status().position
        elif data[0] == 2:
            self.zero = 0.0

    def _profile(self, speed: float, acceleration: float) -> None:
        self.core.parameters = replace(self.core.parameters, profile_velocity=speed,
                                       profile_acceleration=acceleration or 1e9,
                                       profile_deceleration=acceleration or 1e9,
                                       peak_torque=self._peak)

    def _limit_torque(self, limit: float) -> None:
        self.core.parameters = replace(self.core.parameters, peak_torque=limit)

    # --- what the motor reports ----------------------------------------------------------

    def _reported(self) -> Answer:
        status = self.core.status()
        return Answer(self.node_id, status.position - self.zero, status.velocity,
                      status.torque, AMBIENT, self.error)

    def tick(self, now: float) -> None:
        """Servo mode: the status upload at its rate."""
        if not self.attached or self.options.control is not Control.SERVO:
            return
        if now >= self._next_status:
            self._next_status = max(self._next_status + 1 / self.options.status_rate, now)
            self.send(Frame(status_id(self.node_id), pack_status(self._reported(), self.model),
                            extended=True))

    def after_update(self) -> None:
        for fault in self.take_events():
            if fault is not Fault.CONTROLLER_SILENT:     # silence releases, reporting nothing
                self.error = ErrorCode.OVER_CURRENT
            self.core.disable()

    def restart(self) -> None:
        super().restart()
        self.error = ErrorCode.NONE
        self.zero = 0.0                  # a temporary origin is lost with the power

    def readings(self, frame: Frame) -> tuple[Reading, ...] | None:
        """A V2 MIT answer: id and error exact, position, velocity, torque."""
        if (not self.options.mit_on_standard_id or frame.identifier != self.options.reply_id
                or len(frame.data) != 8):
            return None
        answer = unpack_mit_answer(frame.data, self.ranges)
        return (Reading("motor id", answer.motor_id), Reading("error", answer.error),
                *motion_readings(answer))

    @property
    def state_text(self) -> str:
        if self.error is not ErrorCode.NONE:
            return self.error.name.replace("_", " ")
        if self.options.control is Control.SERVO:
            return "SERVO " + ("RUNNING" if self.core.power is Power.ENABLED else "RELEASED")
        return self.mode_text()


def _within(value: float, limit: float) -> float:
    return max(-limit, min(limit, value))


SERVO = {ServoMode.DUTY: CubeMarsDrive._duty, ServoMode.CURRENT: CubeMarsDrive._current,
         ServoMode.CURRENT_BRAKE: CubeMarsDrive._current_brake,
         ServoMode.SPEED: CubeMarsDrive._erpm, ServoMode.POSITION: CubeMarsDrive._position,
         ServoMode.ORIGIN: CubeMarsDrive._origin,
         ServoMode.POSITION_SPEED: CubeMarsDrive._position_speed}
