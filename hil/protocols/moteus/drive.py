"""A simulated moteus controller (the protocol: :mod:`hil.protocols.moteus`), around a
DriveCore whose position, velocity and torque are the controller's output shaft (rad at
the drive; the registers count revolutions).

A frame is served as the firmware serves it (fw/moteus_controller.cc ``Write``/``Read``,
mjlib micro_server.cc): its reads answer with the state before the frame's command (the
firmware reads during the frame and applies the command after it, in ``Poll``); a write of
the mode (0x000) starts a new command from the defaults (``command_ = {}``) and makes the
frame a command; the position registers (0x020-0x02d, shadows 0x042-0x048) fill it.

The modes (registers.md "0x000 - Mode"; fw/bldc_servo_control.h ``ISR_MaybeChangeMode``,
``ISR_DoControl``):

* 0 stopped: no torque; clears a fault and the position timeout.
* 10 position: ``torque = kp kp_scale (p - x) + kd kd_scale (v - x') + feed-forward``,
  within the maximum torque (0x025, NaN: the controller's) and the drive's peak; a NaN
  position holds where the control position is (where the axis is, from stopped); a NaN
  velocity is 0. hil's simplifications: the velocity and acceleration limits (0x028, 0x029)
  and the stop position (0x026) are kept and read back, not applied (the command is
  followed at once, as the firmware does with both limits off), and the control position
  does not advance between commands at the commanded velocity.
* the watchdog (0x027; 0: ``servo.default_timeout_s``, the drive's ``watchdog_timeout``;
  NaN: none): a position command not followed by another within it puts the controller in
  11, position timeout (fw ``ISR_DoControl``), where it damps the output as zero velocity
  mode does (``servo.timeout_mode`` 12 as it ships) with at most
  ``servo.timeout_max_torque_Nm`` (5 N·m), until a stop; position commands meanwhile are
  ignored (fw ``ISR_MaybeChangeMode``).
* 12 zero velocity: ``kd kd_scale (0 - x')``; 11 written: the timeout's behaviour.
* 15 brake: reported; the shorted windings' drag is not simulated (no torque).
* 5-9, 13, 14 (PWM, voltage, current, stay within, inductance): not simulated; hil stops
  and reports stopped (hil's choice), logging it once.
* a fault hil raises (``hil sim --fault``'s following error, a position limit) is mode 1
  with a fault code (:data:`FAULT_CODES`), left only by a stop.
"""

from __future__ import annotations

import logging
import math
from contextlib import AbstractContextManager
from dataclasses import replace

from hil.bus_config.types import DriveConfig
from hil.can.frame import Frame
from hil.can.router import Subscription
from hil.drives.core import DriveCore
from hil.drives.definitions import Fault, Mode as CoreMode, Power, SilenceReaction
from hil.drives.profile import DriveProfile, Reading
from hil.protocols.moteus import (
    BROADCAST, REPLY_REQUESTED, TURN, Moteus, MoteusOptions, identifier, moteus_frame,
)
from hil.protocols.moteus import multiplex
from hil.protocols.moteus.models import AMBIENT, SUPPLY
from hil.protocols.moteus.registers import (
    COMMAND_DEFAULTS, FLOAT, INT32, INT32_ONLY, READ_ONLY, READ_ONLY_UNMODELLED,
    REGISTER_MAP_VERSION, SHADOWS, TAKEN_UNMODELLED, Mode, Register, from_raw, scale_of,
    to_raw,
)

log = logging.getLogger(__name__)

#: core faults -> fault code (registers.md "0x00f - Fault code"): hil's mapping, the nearest
#: in meaning; any other fault is a motor driver fault (33)
FAULT_CODES = {Fault.POSITION_LIMIT: 39, Fault.FOLLOWING_ERROR: 49}
MOTOR_DRIVER_FAULT = 33
#: ``servo.timeout_max_torque_Nm`` as it ships (fw/bldc_servo_structs.h)
TIMEOUT_MAX_TORQUE = 5.0
#: the modes hil runs; others written are taken as a stop (the module doc)
SIMULATED = {Mode.STOPPED, Mode.POSITION, Mode.POSITION_TIMEOUT, Mode.ZERO_VELOCITY,
             Mode.BRAKE}
#: registers.md "0x00c - Home state": 1 the rotor's encoder (every moteus has its onboard
#: one), 2 after a "set output" command
HOME_ROTOR, HOME_OUTPUT = 1, 2


class MoteusDrive(DriveProfile, multiplex.RegisterServer):
    """One moteus controller on a bus, serving its registers."""

    protocol = Moteus

    def __init__(self, config: DriveConfig, core: DriveCore, lock: AbstractContextManager):
        super().__init__(config, core, lock)
        self.options: MoteusOptions = config.options or MoteusOptions()
        self.mode = Mode.STOPPED
        self.fault_code = 0
        #: the command as the last mode write began it and the frame's writes filled it
        #: (the firmware's ``command_``), by register
        self.command = dict(COMMAND_DEFAULTS)
        self.home = HOME_ROTOR
        #: the core's position (rad) where the output reads 0 revolutions
        self.offset = 0.0
        self._peak = core.parameters.peak_torque
        self._default_timeout = core.parameters.watchdog_timeout
        self._commanded: int | None = None        # a mode written in this frame
        self._target = math.nan                    # the control position (rad), position mode
        self._reply: Frame | None = None
        self._warned: set[int] = set()
        self._born = self.clock()
        core.set_mode(CoreMode.IMPEDANCE)
        core.silence_reaction = SilenceReaction.NONE      # the timeout is the profile's
        self._watchdog(0.0)

    # --- the bus ---------------------------------------------------------------------------

    def subscriptions(self) -> list[Subscription]:
        """Frames to its id or to every controller's (0x7F), any source, reply bit or not;
        with its prefix above (29-bit), or none (11-bit or 29-bit)."""
        prefix = self.options.can_prefix << 16
        found = [Subscription(prefix | destination, self.on_frame, True, mask=0x1FFF00FF)
                 for destination in (self.node_id, BROADCAST)]
        if not prefix:
            found += [Subscription(destination, self.on_frame, mask=0xFF)
                      for destination in (self.node_id, BROADCAST)]
        return found

    def on_frame(self, frame: Frame) -> None:
        if frame.remote or frame.error:
            return
        respond = bool(frame.identifier & REPLY_REQUESTED)
        with self.lock:
            self._commanded = None
            payload = multiplex.serve(frame.data, self, respond)
            if self._commanded is not None:
                self._apply(self._commanded)
            if respond:
                # fw/fdcan_micro_server.h AsyncWrite: FD where the request was or the reply
                # needs it, BRS as the request had it
                self._reply = moteus_frame(
                    identifier(self.node_id, (frame.identifier >> 8) & 0x7F, False,
                               self.options.can_prefix),
                    payload, fd=frame.fd or len(payload) > 8, brs=frame.bitrate_switch)
                self.on_command(self)

    def take_replies(self) -> list[Frame]:
        reply, self._reply = self._reply, None
        return [reply] if reply is not None else []

    # --- registers (multiplex.RegisterServer) ------------------------------------------------

    def write(self, register: int, raw: int | float, kind: int) -> int:
        if register == Register.MODE:
            # fw Write: kUnknownRegister past the last mode (a NaN or negative one too:
            # hil's choice, where the firmware's int8 cast is undefined)
            if not (math.isfinite(raw) and 0 <= int(raw) < len(Mode)):
                return multiplex.UNKNOWN_REGISTER
            mode = int(raw)
            self._commanded = mode
            self.command = dict(COMMAND_DEFAULTS)
            return 0
        target = SHADOWS.get(register, register)
        if target in self.command:
            self.command[target] = from_raw(raw, scale_of(target), kind)
        elif register in (Register.SET_OUTPUT_NEAREST, Register.SET_OUTPUT_EXACT):
            self._set_output(from_raw(raw, scale_of(register), kind),
                             register == Register.SET_OUTPUT_EXACT)
        elif register in READ_ONLY or register in READ_ONLY_UNMODELLED:
            return multiplex.NOT_WRITABLE
        elif register not in TAKEN_UNMODELLED:
            return multiplex.UNKNOWN_REGISTER
        return 0

    def read(self, register: int, kind: int) -> int | float | None:
        if register in INT32_ONLY and kind != INT32:
            return None
        value = (self._milliseconds(kind) if register == Register.MILLISECOND_COUNTER
                 else self._value(SHADOWS.get(register, register)))
        return None if value is None else to_raw(value, scale_of(register), kind)

    def _value(self, register: int) -> float | None:
        """A register's value in its own units (revolutions, Hz, N·m, ...); None: one hil
        does not serve (answered as unknown)."""
        if register in self.command:
            return self.command[register]
        status = self.core.status()
        position = (status.position - self.offset) / TURN
        control = (self._target - self.offset) / TURN
        values = {
            Register.MODE: self.mode, Register.POSITION: position,
            Register.VELOCITY: status.velocity / TURN, Register.TORQUE: status.torque,
            # hil's: the motor's linear torque constant, no d-axis current, no losses
            Register.Q_CURRENT: status.torque / self.options.motor.torque_constant,
            Register.D_CURRENT: 0.0, Register.POWER: status.torque * status.velocity,
            # no thermistor (servo.enable_motor_temperature off as it ships)
            Register.MOTOR_TEMPERATURE: math.nan,
            # the command is the control position at once (the module doc)
            Register.TRAJECTORY_COMPLETE: int(self.mode == Mode.POSITION),
            Register.HOME_STATE: self.home, Register.VOLTAGE: SUPPLY,
            Register.TEMPERATURE: AMBIENT, Register.FAULT: self.fault_code,
            Register.CONTROL_POSITION: control,
            Register.CONTROL_VELOCITY: self.command[Register.COMMAND_VELOCITY],
            Register.CONTROL_TORQUE: status.torque,
            Register.POSITION_ERROR: position - control,
            Register.VELOCITY_ERROR: status.velocity / TURN - self.command[0x021],
            Register.REGISTER_MAP_VERSION: REGISTER_MAP_VERSION,
        }
        return values.get(register)

    def _milliseconds(self, kind: int) -> int:
        """Milliseconds since it started, wrapping at the queried type (registers.md "0x070";
        fw Read: the counter cast to the type, as float modulo 2^23)."""
        milliseconds = int((self.clock() - self._born) * 1000)
        return milliseconds % 8388608 if kind == FLOAT else milliseconds
    def _set_output(self, position: float, exact: bool) -> None:
        """0x131: the output reads ``position`` here; 0x130: the whole number of turns that
        brings it closest (registers.md "0x130", "0x131"; the output's turn, the controller's
        rotor-to-output ratio being the bus config's transmission)."""
        here = (self.core.status().position - self.offset) / TURN
        shift = position - here if exact else round(position - here)
        self.offset -= shift * TURN
        self.home = HOME_OUTPUT

    # --- commands --------------------------------------------------------------------------

    def _apply(self, mode: int) -> None:
        """The frame's command, once it is served (fw ``Poll``: ``bldc_.Command``)."""
        if mode == Mode.STOPPED:
            self._stop()
            return
        if self.mode in (Mode.FAULT, Mode.POSITION_TIMEOUT):
            return                        # only a stop leaves them
        if mode < Mode.PWM:
            return                        # not commandable (fw PrepareCommand)
        if mode not in SIMULATED:
            if mode not in self._warned:
                self._warned.add(mode)
                log.warning("node %d: moteus mode %d (%s) is not simulated: taken as a stop",
                            self.node_id, mode, Mode(mode).name.lower())
            self._stop()
            return
        if mode == Mode.POSITION:
            self._position()
        elif mode == Mode.BRAKE:
            self._stop()
            self.mode = Mode.BRAKE
        elif mode == Mode.POSITION_TIMEOUT:
            self._time_out()
        else:
            self._zero_velocity(Mode.ZERO_VELOCITY, _finite(self.command[Register.KD_SCALE], 1.0),
                                self._peak)

    def _stop(self) -> None:
        self.core.disable()
        self.core.reset_fault()
        self.mode, self.fault_code, self._target = Mode.STOPPED, 0, math.nan
        self._watchdog(0.0)

    def _enable(self, mode: Mode, peak: float) -> None:
        if self.core.power is not Power.ENABLED:
            self.core.enable()
        self.mode = mode
        if peak != self.core.parameters.peak_torque:
            self.core.parameters = replace(self.core.parameters, peak_torque=peak)

    def _position(self) -> None:
        command = self.command
        timeout = command[Register.WATCHDOG_TIMEOUT]
        self._watchdog(self._default_timeout if timeout == 0.0 else
                       0.0 if not math.isfinite(timeout) else timeout)
        # only a command feeds it (fw bldc_servo.cc: the command's timeout_s becomes the
        # status' when the command is applied); a query does not
        self.core.new_setpoint(now=self.clock())
        # NaN: registers.md's meaning (max torque the controller's, position held, velocity
        # 0); an infinite value, or a NaN where the document gives NaN none, is taken as NaN
        # or as the register's default (hil's choice: no full torque from garbage)
        limit = _finite(command[Register.MAXIMUM_TORQUE], self._peak)
        peak = min(abs(limit), self._peak)
        if self.mode != Mode.POSITION or math.isnan(self._target):
            self._target = self.core.status().position
        self._enable(Mode.POSITION, peak)
        position = command[Register.COMMAND_POSITION]
        if math.isfinite(position):
            self._target = position * TURN + self.offset
        kp_scale = _finite(command[Register.KP_SCALE], 1.0)
        # registers.md "0x024 - Kd scale": no more than the kp scale
        kd_scale = min(_finite(command[Register.KD_SCALE], 1.0), kp_scale)
        self.core.new_setpoint(
            position=self._target,
            velocity=_finite(command[Register.COMMAND_VELOCITY], 0.0) * TURN,
            torque=_finite(command[Register.FEEDFORWARD_TORQUE], 0.0),
            stiffness=self.options.kp * kp_scale / TURN, damping=self.options.kd * kd_scale / TURN)

    def _zero_velocity(self, mode: Mode, kd_scale: float, peak: float) -> None:
        self._watchdog(0.0)
        self._enable(mode, peak)
        self._target = math.nan
        self.core.new_setpoint(position=self.core.status().position, velocity=0.0, torque=0.0,
                               stiffness=0.0, damping=self.options.kd * kd_scale / TURN)

    def _time_out(self) -> None:
        """Position timeout: zero velocity mode's damping within the timeout's torque."""
        self._zero_velocity(Mode.POSITION_TIMEOUT, 1.0, min(TIMEOUT_MAX_TORQUE, self._peak))

    def _watchdog(self, timeout: float) -> None:
        if timeout != self.core.parameters.watchdog_timeout:
            self.core.parameters = replace(self.core.parameters, watchdog_timeout=timeout)

    # --- the simulator's side --------------------------------------------------------------

    def after_update(self) -> None:
        for fault in self.take_events():
            if fault is Fault.CONTROLLER_SILENT:
                if self.mode == Mode.POSITION:
                    self._time_out()
                continue
            self.core.raise_fault(fault)
            self.mode, self.fault_code = Mode.FAULT, FAULT_CODES.get(fault, MOTOR_DRIVER_FAULT)
            self._watchdog(0.0)

    def fault_words(self, fault: Fault) -> str:
        if fault is Fault.CONTROLLER_SILENT:
            return "no command within the watchdog timeout: mode 11, position timeout"
        return f"{fault.text}: mode 1, fault {FAULT_CODES.get(fault, MOTOR_DRIVER_FAULT)}"

    def restart(self) -> None:
        super().restart()
        self._stop()
        self.command, self.offset, self.home = dict(COMMAND_DEFAULTS), 0.0, HOME_ROTOR
        self._born = self.clock()

    def readings(self, frame: Frame) -> tuple[Reading, ...] | None:
        """A reply's registers: mode and fault exact, position, velocity (revolutions) and
        torque within tolerances."""
        if (frame.identifier >> 8) & 0x7F != self.node_id or frame.identifier & REPLY_REQUESTED:
            return None
        found: list[Reading] = []
        for part in multiplex.parse(frame.data):
            if not isinstance(part, multiplex.Values) or part.base != multiplex.REPLY:
                continue
            for register, raw in part.values.items():
                value = from_raw(raw, scale_of(register), part.kind) \
                    if register in (Register.POSITION, Register.VELOCITY, Register.TORQUE) \
                    else raw
                reading = READINGS.get(register)
                if reading is not None:
                    found.append(Reading(reading[0], value, *reading[1:]))
        return tuple(found) or None

    @property
    def state_text(self) -> str:
        if self.mode == Mode.FAULT:
            return f"FAULT ({self.fault_code})"
        return Mode(self.mode).name.replace("_", " ")


def _finite(value: float, default: float) -> float:
    return value if math.isfinite(value) else default


#: what a replay compares of a reply's registers: name, quantity, scale to SI
READINGS = {Register.MODE: ("mode",), Register.FAULT: ("fault",),
            Register.POSITION: ("position", "position", TURN),
            Register.VELOCITY: ("velocity", "velocity", TURN),
            Register.TORQUE: ("torque", "torque", 1.0)}
