"""A simulated MyActuator RMD-X motor (the protocol: :mod:`hil.protocols.myactuator`, the
frames: :mod:`.codec`), around a DriveCore at the output shaft (the built-in gear folded in,
as every frame's angles and speeds are the output shaft's).

What it does, each with the section of protocol V4.2 it follows:

* Every 8-byte command on ``0x140 + id``, and on ``0x280`` (§3), is answered on ``0x240 +
  id`` (except 0x76, §2.25.3, and 0xB6 enabling active replies, §2.33.3); the motion mode
  command on ``0x400 + id`` on ``0x500 + id`` (§5.3); the CANID command on ``0x300`` (§4.3).
* No enable command: a control command (0xA1-0xA8, §2.19-2.23) "can be run when the motor
  is not faulty" and powers it in its loop; 0x80 "turns off the motor output" (§2.17), 0x81
  stops it where it is, in closed loop (§2.18); 0x78 locks the brake, "the motor can no
  longer run" (§2.27). A read or setting command never moves the motor.
* 0xA1 "cannot open the brake directly": a motor with a holding brake (the bus config's
  ``holding_brake``) runs torque commands only after 0x77 (§2.19.1).
* The communication interruption protection (0xB3, §2.30): past the time without a frame
  the output is cut and the brake locked; the next control command runs again. Off (0)
  as hil ships it (the document gives no factory value).
* Errors (status 1, §2.14): a fault hil injects is reported as OVER_CURRENT, a level-1
  fault the motor "cannot recover from" without a restart (§8.2): until 0x76 or a power
  cycle, control commands move nothing. The temperature is the ambient 25 °C (no heating
  is modelled).
* Zero, CAN id, baud rate written to ROM take effect at the next start (§2.10.1, §2.34.4
  index 5; §2.31.1); 0x63's zero likewise (hil's reading: §2.9 is silent).
* Frames the motor cannot take (29 bits on its ids, another length, an unknown command
  byte) are ignored unanswered, as a controller filtering standard ids and a firmware
  dispatching on the command byte would (hil's reading: the document is silent), and logged
  once per id and kind naming the bus and the id.
"""

from __future__ import annotations

import logging
import struct
from contextlib import AbstractContextManager
from dataclasses import replace

from hil.bus_config.types import BusConfig, DriveConfig
from hil.can.frame import Frame
from hil.can.router import Subscription
from hil.drives.core import DriveCore
from hil.drives.definitions import Fault, Mode, Power, SilenceReaction
from hil.drives.profile import DriveProfile, Reading
from hil.protocols.mit import unpack_command_values
from hil.protocols.mit.drive import follow
from hil.protocols.myactuator import MyActuator, MyActuatorOptions, command_id, reply_id
from hil.protocols.myactuator.codec import (
    CANID_SETTING_ID, CONTROL, ENCODER_LINES, MIT_BASE, MIT_RANGES, MIT_REPLY_BASE,
    MOTOR_IDS, MULTI_MOTOR_ID, Command, ErrorState, RunMode, pack_mit_reply,
    unpack_mit_reply, unpack_state, value_of,
)
from hil.protocols.myactuator.reads import DEGREE, MotorReads
from hil.protocols.myactuator.settings import Settings

log = logging.getLogger(__name__)


class MyActuatorDrive(MotorReads, DriveProfile):
    """One RMD-X motor on a bus."""

    protocol = MyActuator

    def __init__(self, config: DriveConfig, core: DriveCore, lock: AbstractContextManager):
        super().__init__(config, core, lock)
        self.options: MyActuatorOptions = config.options or MyActuatorOptions()
        self.model = self.options.model
        self.settings = Settings(next_id=config.node_id)
        self.error = ErrorState(0)
        self.brake_released = False       # at power-up the brake holds (§2.27.1)
        self.run_mode = RunMode.NONE
        self.zero = 0.0                   # rad: the output's position at the motor's zero
        self.booted_at = self.clock()
        self.bus_name: str | None = None
        self._warned: set[tuple[int, bool, str]] = set()
        self._replies: list[Frame] = []
        # the CAN timeout cuts the output (§2.30.1)
        core.silence_reaction = SilenceReaction.DISABLE

    def on_bus(self, bus: BusConfig) -> None:
        self.bus_name = bus.name

    @property
    def where(self) -> str:
        """The motor in a log line: its bus (where known) and id."""
        bus = "" if self.bus_name is None else f"bus '{self.bus_name}' "
        return f"{bus}node {self.node_id}"

    # --- bus ----------------------------------------------------------------------------

    def subscriptions(self) -> list[Subscription]:
        own = (command_id(self.node_id), MULTI_MOTOR_ID, CANID_SETTING_ID,
               MIT_BASE + self.node_id)
        return [Subscription(command_id(self.node_id), self._on_single),
                Subscription(MULTI_MOTOR_ID, self._on_multi),
                Subscription(CANID_SETTING_ID, self._on_canid),
                Subscription(MIT_BASE + self.node_id, self._on_mit),
                *(Subscription(identifier, self._on_extended, extended=True)
                  for identifier in own)]

    def _on_extended(self, frame: Frame) -> None:
        self.diagnose(frame, "a 29-bit frame on its id; it takes standard frames only "
                             "(protocol V4.2 §1.1.2) and ignores it")

    def diagnose(self, frame: Frame, what: str) -> None:
        """Log, once per id and kind, a frame the motor ignores."""
        key = (frame.identifier, frame.extended, what)
        if key not in self._warned:
            self._warned.add(key)
            log.warning("%s (MyActuator RMD), id 0x%03X: %s", self.where, frame.identifier,
                        what)

    def _on_single(self, frame: Frame) -> None:
        self._take(frame, reply_id(self.node_id))

    def _on_multi(self, frame: Frame) -> None:
        """§3: the same command as a single motor's, each motor answering on its own id;
        not heard with the CANID filter on (§2.34.4, index 2)."""
        if not self.settings.can_filter:
            self._take(frame, reply_id(self.node_id))

    def _on_canid(self, frame: Frame) -> None:
        """§4: only the CANID command (0x79) is taken here; another motor's read reply (its
        reply id in bytes 6-7) is no command."""
        data = frame.data
        if self.settings.can_filter or (len(data) == 8 and data[2] == 1 and data[6] | data[7]):
            return
        if data and data[0] != Command.CANID:
            self.diagnose(frame, f"command byte 0x{data[0]:02X} on the CANID setting id (§4 "
                                 "takes 0x79 only); ignored, unanswered")
            return
        self._take(frame, CANID_SETTING_ID)

    def _take(self, frame: Frame, answer_id: int) -> None:
        data = frame.data
        if len(data) != 8:
            self.malformed += 1
            self.diagnose(frame, f"{len(data)} data bytes, not 8 (§1.1.2); ignored")
            return
        handler = COMMANDS.get(data[0])
        if handler is None:
            self.malformed += 1
            self.diagnose(frame, f"unknown command byte 0x{data[0]:02X}; ignored, unanswered")
            return
        with self.lock:
            self.heard()
            answer = handler(self, bytes(data))
            self._replies = [] if answer is None else [Frame(answer_id, answer)]
            self.on_command(self)

    def _on_mit(self, frame: Frame) -> None:
        """§5: ``IqRef = [kp (p_des - p) + kd (v_des - v) + t_ff] KT``, answered with the
        position, speed and torque (hil's reading: the command powers the motor, as the
        control commands do; a faulty motor follows nothing)."""
        if len(frame.data) != 8:
            self.malformed += 1
            self.diagnose(frame, f"{len(frame.data)} data bytes, not 8 (§5.2); ignored")
            return
        with self.lock:
            self.heard()
            command = unpack_command_values(bytes(frame.data), MIT_RANGES)
            if self._powered(Mode.IMPEDANCE):
                self.run_mode = RunMode.POSITION
                follow(self.core, command, self.zero)
            status = self.core.status()
            self._replies = [Frame(MIT_REPLY_BASE + self.node_id, pack_mit_reply(
                self.node_id, status.position - self.zero, status.velocity, status.torque))]
            self.on_command(self)

    def take_replies(self) -> list[Frame]:
        replies, self._replies = self._replies, []
        return replies

    # --- closed-loop control (§2.19-2.23) ----------------------------------------------

    def _powered(self, mode: Mode) -> bool:
        """Run in ``mode`` unless faulty (§2.19.1); whether it runs. The brake is released
        with it (hil's reading of §2.19.1: only 0xA1 "cannot open the brake directly")."""
        if self.error or self.core.power is Power.FAULT:
            return False
        self.brake_released = True
        if self.core.mode is not mode or self.core.power is not Power.ENABLED:
            self.core.set_mode(mode)
            self.core.enable()
            self.core.hold_position()
        return True

    def _profile(self, speed: float, acceleration: float, deceleration: float) -> None:
        """A planning's figures (dps, dps/s); 0 plans nothing: "directly track the target"
        (§2.21.1), "limited by the maximum current output capability" (§2.20.2)."""
        limit = self.config.max_velocity
        self.core.parameters = replace(
            self.core.parameters, profile_velocity=min(speed * DEGREE or limit, limit),
            profile_acceleration=acceleration * DEGREE or 1e9,
            profile_deceleration=deceleration * DEGREE or 1e9)

    def _torque(self, data: bytes) -> bytes:
        if not (self.config.holding_brake and not self.brake_released) and (
                self._powered(Mode.TORQUE)):
            self.run_mode = RunMode.CURRENT
            amperes = struct.unpack_from("<h", data, 4)[0] / 100
            self.core.new_setpoint(torque=amperes * self.model.torque_constant)
        return self._state_reply(data)

    def _speed(self, data: bytes) -> bytes:
        if self._powered(Mode.PROFILE_VELOCITY):
            self.run_mode = RunMode.SPEED
            accelerations = self.settings.acceleration
            self._profile(0.0, accelerations[2], accelerations[3])
            self.core.new_setpoint(velocity=value_of(data) / 100 * DEGREE)
        return self._state_reply(data)

    def _move(self, data: bytes, target: float) -> bytes:
        """A position move to ``target`` (rad from the zero) at most ``maxSpeed`` (bytes 2-3,
        dps), on the position planning's acceleration (§2.21.1), within the angle limits
        function control sets (§2.34.4, indexes 6 and 7)."""
        if self._powered(Mode.PROFILE_POSITION):
            self.run_mode = RunMode.POSITION
            accelerations = self.settings.acceleration
            self._profile(struct.unpack_from("<H", data, 2)[0], accelerations[0],
                          accelerations[1])
            low, high = self.settings.angle_limits
            self.core.move_to(min(max(target, low * DEGREE), high * DEGREE) + self.zero)
        return self._state_reply(data)

    def _absolute(self, data: bytes) -> bytes:
        return self._move(data, value_of(data) / 100 * DEGREE)

    def _incremental(self, data: bytes) -> bytes:
        """"with the current position as the starting point" (§2.23.1)."""
        here = self.core.status().position - self.zero
        return self._move(data, here + value_of(data) / 100 * DEGREE)

    def _single_turn(self, data: bytes) -> bytes:
        """§2.22: to an angle 0-359.99° of the turn, clockwise (0, the angle's increasing
        sense, §2.13.3) or counterclockwise (1); answered with the encoder's pulses."""
        here = (self.core.status().position - self.zero) / DEGREE
        goal = struct.unpack_from("<H", data, 4)[0] / 100 % 360
        step = (goal - here) % 360 if data[1] == 0 else -((here - goal) % 360)
        answer = bytearray(self._move(data, (here + step) * DEGREE))
        struct.pack_into("<H", answer, 6, self.pulses(self.core.status().position - self.zero)
                         % ENCODER_LINES)
        return bytes(answer)

    def _shutdown(self, data: bytes) -> bytes:
        self.core.disable()
        self.run_mode = RunMode.NONE
        return data

    def _stop(self, data: bytes) -> bytes:
        """"the closed-loop mode where the motor is still running, just stop the motor
        speed" (§2.18.1): held where it is."""
        if self.core.power is Power.ENABLED:
            self.core.set_mode(Mode.PROFILE_POSITION)
            self.core.hold_position()
        return data

    def _brake(self, data: bytes) -> bytes:
        """0x77 releases the brake; 0x78 locks it and "the motor can no longer run"
        (§2.27.1)."""
        self.brake_released = data[0] == Command.BRAKE_RELEASE
        if not self.brake_released:
            self.core.disable()
        return data

    def _reset(self, data: bytes) -> None:
        """§2.25: the motor restarts and does not answer."""
        self.restart()

    def _settings(self, data: bytes) -> bytes | None:
        """Settings commands (:class:`.settings.Settings`); the CAN timeout (0xB3) into the
        core."""
        answer = self.settings.command(self, data)
        if data[0] == Command.CAN_TIMEOUT:
            self.core.parameters = replace(self.core.parameters,
                                           watchdog_timeout=self.settings.timeout_ms / 1000)
        return answer

    # --- the core's events, restarts ---------------------------------------------------

    def after_update(self) -> None:
        for fault in self.take_events():
            if fault is Fault.CONTROLLER_SILENT:
                self.brake_released = False      # "cut off the output, brake lock" (§2.30.1)
                continue
            self.error |= ErrorState.OVER_CURRENT
            self.core.disable()

    def restart(self) -> None:
        """As after a power cycle: disabled, errors cleared, the ROM's zero, id and CAN timeout
        taken (§2.10.1, §2.34.4)."""
        super().restart()
        self.error = ErrorState(0)
        self.brake_released = False
        self.run_mode = RunMode.NONE
        self.settings.restart()
        self.zero = self.settings.rom_zero
        self.booted_at = self.clock()
        if self.settings.next_id != self.node_id and self.settings.next_id in MOTOR_IDS:
            router = self.router
            self.detach()
            self.node_id = self.settings.next_id
            if router is not None:
                self.attach(router)

    def fault_words(self, fault: Fault) -> str:
        if fault is Fault.CONTROLLER_SILENT:
            return f"{fault.text} (0xB3's communication interruption protection: output cut)"
        return f"{fault.text} (status 1: {ErrorState.OVER_CURRENT.name})"

    @property
    def state_text(self) -> str:
        if self.error:
            return " ".join(flag.name or "" for flag in ErrorState if flag in self.error)
        return "RUNNING " + self.run_mode.name if self.core.power is Power.ENABLED else "OFF"

    def readings(self, frame: Frame) -> tuple[Reading, ...] | None:
        """The motion a reply carries, for a replay's comparison; the rest exact."""
        data = frame.data
        if frame.identifier == MIT_REPLY_BASE + self.node_id and len(data) == 8:
            node, position, velocity, torque = unpack_mit_reply(data)
            return (Reading("motor id", node), Reading("position", position, "position"),
                    Reading("velocity", velocity, "velocity"),
                    Reading("torque", torque, "torque"))
        if frame.identifier == reply_id(self.node_id) and len(data) == 8 and (
                data[0] in CONTROL or data[0] == Command.READ_STATUS_2):
            state = unpack_state(data)
            return (Reading("command", data[0]), Reading("temperature", state.temperature),
                    Reading("iq", state.iq * self.model.torque_constant, "torque"),
                    Reading("speed", state.speed, "velocity", DEGREE),
                    Reading("angle", state.angle, None if data[0] ==
                            Command.SINGLE_TURN_POSITION else "position", DEGREE))
        return None


#: each command byte's handler: the answer's data (None: no answer)
COMMANDS = {
    Command.TORQUE: MyActuatorDrive._torque, Command.SPEED: MyActuatorDrive._speed,
    Command.ABSOLUTE_POSITION: MyActuatorDrive._absolute,
    Command.SINGLE_TURN_POSITION: MyActuatorDrive._single_turn,
    Command.INCREMENTAL_POSITION: MyActuatorDrive._incremental,
    Command.SHUTDOWN: MyActuatorDrive._shutdown, Command.STOP: MyActuatorDrive._stop,
    Command.BRAKE_RELEASE: MyActuatorDrive._brake, Command.BRAKE_LOCK: MyActuatorDrive._brake,
    Command.READ_MULTI_TURN_ENCODER: MyActuatorDrive._encoder,
    Command.READ_MULTI_TURN_ORIGINAL: MyActuatorDrive._encoder,
    Command.READ_MULTI_TURN_ZERO_OFFSET: MyActuatorDrive._encoder,
    Command.READ_SINGLE_TURN_ENCODER: MyActuatorDrive._single_turn_encoder,
    Command.READ_MULTI_TURN_ANGLE: MyActuatorDrive._angle,
    Command.READ_SINGLE_TURN_ANGLE: MyActuatorDrive._angle,
    Command.READ_STATUS_1: MyActuatorDrive._status_1,
    Command.READ_STATUS_2: MyActuatorDrive._state_reply,
    Command.READ_STATUS_3: MyActuatorDrive._status_3,
    Command.READ_OPERATING_MODE: MyActuatorDrive._operating_mode,
    Command.READ_POWER: MyActuatorDrive._power, Command.READ_RUNTIME: MyActuatorDrive._runtime,
    Command.RESET: MyActuatorDrive._reset,
    **{command: MyActuatorDrive._settings for command in (
        Command.READ_PID, Command.WRITE_PID_RAM, Command.WRITE_PID_ROM,
        Command.READ_ACCELERATION, Command.WRITE_ACCELERATION, Command.WRITE_ENCODER_ZERO,
        Command.WRITE_CURRENT_ZERO, Command.CANID, Command.READ_VERSION_DATE,
        Command.CAN_TIMEOUT, Command.BAUD_RATE, Command.READ_MODEL, Command.ACTIVE_REPLY,
        Command.FUNCTION_CONTROL)},
}
