"""A simulated Damiao DM-J motor (the protocol: :mod:`hil.protocols.damiao`), around a
DriveCore: the output shaft's position, velocity and torque are the drive's (its
transmission in the bus config folds the built-in gear in, as the motor's ``Gr`` register
does).

What the registers mean here: CTRL_MODE selects which command id moves the motor; PMAX, VMAX
and TMAX map MIT commands and every feedback; TIMEOUT (x 50 us, 0 off) is the watchdog
after which the motor disables itself and reports LOST_COMMUNICATION until a clear-error
frame (it counts only while the motor is enabled, and every frame on the motor's id, of
any mode, special frames included, restarts it, as the DM4310's firmware does: its
communication age, recovered in github.com/umeow0716/damiao_firmware app/src/safety.c);
ACC and DEC (rad/s², DEC negative; 0: no ramp) ramp the position-velocity and velocity
modes; p_m and xout read the position; VBus, Tpcb and Tmtr read the supply and no
heating. MST_ID and ESC_ID are kept, saved and read back, and the motor keeps answering on
the bus config's ids (hil's choice: the maker's documents do not say when a new id applies,
and a bench's ids are its config's). A write is range-checked as the DM4310's firmware
checks it (:data:`hil.protocols.damiao.registers.WRITABLE`): one the register cannot take
leaves it as it was, and the answer carries the value it kept. The others are kept and
read back as written. Saved values (0xAA, taken only while the motor is disabled, as the
firmware takes them) survive a restart within the run (``hil sim --fault
restart:...``); unsaved ones are lost with it.

On CAN FD (CAN_BR, register 35, an FD code; by default the bus' rates) every answer is an FD
frame with the bit-rate switch; a frame whose format is not the motor's is taken all the
same and reported once (:mod:`hil.protocols.damiao.fd`).

A command is never left over from another mode or another enable: as the firmware keeps
one command and zeroes it when CTRL_MODE changes (parameter_protocol.c, write_register)
and when the motor is disabled (app_commands.c), the motor enabled, or switched to a new
mode while enabled, runs that mode's zeroed command (:meth:`DamiaoDrive._zero_command`)
until the master sends one. The firmware takes a CTRL_MODE write while enabled, and so
does hil.
"""

from __future__ import annotations

import math
import struct
from contextlib import AbstractContextManager
from dataclasses import replace

from hil.bus_config.types import BusConfig, DriveConfig
from hil.can.frame import Frame
from hil.can.router import Subscription
from hil.drives.core import DriveCore
from hil.drives.definitions import Fault, Mode, Power, SilenceReaction
from hil.drives.profile import Reading
from hil.errors import ConfigError
from hil.protocols.damiao import (
    CLEAR_ERROR, DISABLE, ENABLE, SAVE_ZERO, ControlMode, Damiao, DamiaoOptions, Op,
    REGISTER_ID, STATE_TEXT, State, feedback_head, is_register_answer, unpack_feedback,
)
from hil.protocols.damiao.fd import FormatWatch, is_fd_code, rate_code
from hil.protocols.damiao.registers import (
    AMBIENT, ID_REGISTERS, REGISTERS, TIMEOUT_UNIT, accepts, initial_values,
)
from hil.protocols.mit import MitRanges, frame_on_bus, pack_answer, unpack_command_values
from hil.protocols.mit.drive import MitFamilyDrive, follow, motion_readings
from hil.protocols.mit.family import KD_MAX, KP_MAX

#: the core's mode for each control mode
CORE_MODES = {ControlMode.MIT: Mode.IMPEDANCE, ControlMode.POSITION_VELOCITY:
              Mode.PROFILE_POSITION, ControlMode.VELOCITY: Mode.PROFILE_VELOCITY,
              ControlMode.FORCE_POSITION: Mode.PROFILE_POSITION}
#: core faults -> the state the motor reports (a following error, as ``hil sim --fault
#: fault:`` injects, is an overload to a motor that has no following-error check)
FAULT_STATES = {Fault.CONTROLLER_SILENT: State.LOST_COMMUNICATION}
#: ACC or DEC of 0: the reference steps at once (rad/s², finite: it multiplies distances)
NO_RAMP = 1e9
#: the temperatures the feedback carries (its whole degrees): the MOSFETs' and the rotor's
_TEMPERATURES = bytes([int(AMBIENT), int(AMBIENT)])
#: the bytes each mode's command carries (the module doc of hil.protocols.damiao); the
#: special frames are MIT's 8
COMMAND_LENGTHS = {ControlMode.MIT: 8, ControlMode.POSITION_VELOCITY: 8,
                   ControlMode.VELOCITY: 4, ControlMode.FORCE_POSITION: 8}
_FORCE_POSITION = struct.Struct("<fHH")
_TWO_FLOATS = struct.Struct("<ff")


class DamiaoDrive(MitFamilyDrive):
    """One DM-J motor on a bus."""

    protocol = Damiao
    options: DamiaoOptions

    def __init__(self, config: DriveConfig, core: DriveCore, lock: AbstractContextManager):
        super().__init__(config, core, lock)
        node_id, options = self.node_id, self.options
        ranges = options.ranges()
        self.registers = initial_values(options.model, node_id, options.reply_id(node_id),
                                        options.control_mode, core.parameters.watchdog_timeout)
        self.registers.update({21: ranges.p_max, 22: ranges.v_max, 23: ranges.t_max})
        self.saved = dict(self.registers)
        self.reply_id = options.reply_id(node_id)
        self.error: State | None = None
        self._peak = core.parameters.peak_torque
        #: each command id of the motor, with the control mode whose commands it takes
        self._modes = {node_id + mode.id_offset: mode for mode in ControlMode}
        # TIMEOUT disables the motor, LOST_COMMUNICATION until cleared (the module doc)
        core.silence_reaction = SilenceReaction.DISABLE
        self._apply_registers()
        self.watch = FormatWatch(f"node {node_id}")

    def on_bus(self, bus: BusConfig) -> None:
        """CAN_BR: the options' code, else the bus' rates' (the module doc)."""
        super().on_bus(bus)
        self.watch.where = f"bus '{bus.name}' node {self.node_id}"
        code = self.options.can_br
        if code is None:
            try:
                code = rate_code(bus.bitrate, bus.fd, bus.data_bitrate)
            except ValueError as error:
                raise ConfigError.single(
                    f"bus '{bus.name}' drive node {self.node_id}: {error}",
                    line=self.config.line, hint="give the bus rates a DM-J motor runs, or "
                    "the drive 'options: {can_br: N}'") from None
        self.registers[35] = self.saved[35] = code
        self._apply_registers()

    # --- bus ----------------------------------------------------------------------------

    def subscriptions(self) -> list[Subscription]:
        return [*(Subscription(identifier, self.on_frame) for identifier in self._modes),
                Subscription(REGISTER_ID, self._on_register)]

    def of_other_length(self, frame: Frame) -> Frame | None:
        """A frame on one of the motor's command ids: the firmware reads 8 data bytes of its
        receive element whatever the DLC (board_mcan_hc32f448.c, ``board_mcan_receive_payload``:
        ``*length = 8``), an FD frame's first 8, so a command as long as its mode's payload
        or longer is taken (openarm_can sends the velocity command in 4 bytes:
        ``pack_vel_control_data``). A shorter one is malformed (hil's choice: the firmware
        would read the element's bytes of an earlier frame after it)."""
        data = frame.data
        if len(data) < COMMAND_LENGTHS[self._modes[frame.identifier]]:
            self.malformed += 1
            return None
        return frame._replace(data=data[:8].ljust(8, b"\0"))

    def apply(self, frame: Frame) -> Frame:
        if frame.fd != self.fd:     # told once (a call less a frame where it matches)
            self.watch.note(frame, self.fd)
        mode, data = self._modes[frame.identifier], frame.data
        if mode is ControlMode.MIT and data in SPECIAL_FRAMES:
            SPECIAL_FRAMES[data](self)
        elif mode is self.control_mode and self.core.power is Power.ENABLED:
            COMMANDS[mode](self, data)
        # else: a command for another mode than CTRL_MODE's, or to a disabled motor: it
        # moves nothing, and the motor answers with its feedback (its state says why)
        return self.answer()

    def answer(self) -> Frame:
        """The feedback frame."""
        status = self.core.status()
        data = pack_answer(feedback_head(self.node_id, self.state),
                           status.position - self.zero, status.velocity, status.torque,
                           self.ranges, _TEMPERATURES)
        return frame_on_bus(self.reply_id, data, self.fd)

    @property
    def state(self) -> State:
        if self.error is not None:
            return self.error
        return State.ENABLED if self.core.power is Power.ENABLED else State.DISABLED

    # --- special frames ---------------------------------------------------------------

    def _enable(self) -> None:
        if self.error is not None or self.core.power is Power.ENABLED:
            return                       # an error stands until cleared (FB); enabled: as is
        self.core.set_mode(CORE_MODES[self.control_mode])
        self.core.enable()
        self._zero_command()             # the command a disable left: zeroed

    def _disable(self) -> None:
        self.core.disable()

    def _save_zero(self) -> None:
        """The zero here, and the command's position with it: the firmware sets it to 0,
        the new zero (app_commands.c, CAN_COMMAND_SET_ZERO), so a move in progress ends
        here."""
        here = self.core.status().position
        self.zero = here
        if self.core.power is not Power.ENABLED:
            return
        if self.control_mode is ControlMode.MIT:
            self.core.new_setpoint(position=here)
        elif self.control_mode is not ControlMode.VELOCITY:
            self.core.move_to(here)

    def _clear_error(self) -> None:
        """The error cleared and the motor disabled, as the firmware does
        (app_commands.c, CAN_COMMAND_CLEAR_FAULT: the motor disarmed)."""
        self.error = None
        if self.core.power is Power.FAULT:
            self.core.reset_fault()
        self.core.disable()

    def _zero_command(self) -> None:
        """The firmware's command zeroed (position, velocity, kp, kd, torque 0), as the
        enabled motor runs it in each mode (motor_control.c): MIT, no torque (kp, kd and
        the feed-forward 0); velocity, the speed brought to 0; position-velocity, a
        velocity limit of 0: stopped where it is; force-position, a current limit of 0: no
        torque."""
        mode = self.control_mode
        self.core.set_mode(CORE_MODES[mode])
        if mode is ControlMode.MIT:
            self.core.new_setpoint(position=self.core.status().position, velocity=0.0,
                                   torque=0.0, stiffness=0.0, damping=0.0)
        elif mode is ControlMode.VELOCITY:
            self._profile(0.0, self._peak)
            self.core.new_setpoint(velocity=0.0)
        else:
            self._profile(0.0, 0.0 if mode is ControlMode.FORCE_POSITION else self._peak)
            self.core.hold_position()

    # --- commands, one per control mode --------------------------------------------------

    def _mit(self, data: bytes) -> None:
        command = unpack_command_values(data, self.ranges)
        if self.core.parameters.peak_torque != self._peak:          # after force-position
            self.core.parameters = replace(self.core.parameters, peak_torque=self._peak)
        follow(self.core, command, self.zero)

    def _position_velocity(self, data: bytes) -> None:
        position, velocity = _TWO_FLOATS.unpack(data)
        self._move(position, abs(velocity), self._peak)

    def _velocity(self, data: bytes) -> None:
        velocity = struct.unpack_from("<f", data)[0]
        if math.isfinite(velocity):
            self._profile(abs(velocity), self._peak)
            self.core.new_setpoint(velocity=velocity)

    def _force_position(self, data: bytes) -> None:
        position, speed, share = _FORCE_POSITION.unpack(data)
        # velocity limit x 100 (0..100 rad/s), torque limit x 10000 as a share of TMAX
        self._move(position, min(speed, 10000) / 100,
                   min(self._peak, min(share, 10000) / 10000 * self.registers[23]))

    def _move(self, position: float, speed: float, torque_limit: float) -> None:
        if math.isfinite(position) and math.isfinite(speed):
            self._profile(speed, torque_limit)
            self.core.move_to(position + self.zero)

    def _profile(self, speed: float, torque_limit: float) -> None:
        self.core.parameters = replace(
            self.core.parameters, profile_velocity=speed, peak_torque=torque_limit,
            profile_acceleration=self.registers[4] or NO_RAMP,
            profile_deceleration=abs(self.registers[5]) or NO_RAMP)

    # --- registers -------------------------------------------------------------------

    def _on_register(self, frame: Frame) -> None:
        data = frame.data[:8]            # an FD frame's first 8 bytes, as a command's
        if len(data) != 8 or (data[0] | (data[1] << 8)) != self.node_id:
            return                       # another motor's, or not a request
        with self.lock:
            self.watch.note(frame, self.fd)
            op, number = data[2], data[3]
            if op == Op.REFRESH:
                self.send(self.answer())
                return
            if op == Op.SAVE:
                if self.core.power is not Power.ENABLED:    # the firmware saves disarmed only
                    self.saved = dict(self.registers)     # no answer: the sources show none
                return
            register = REGISTERS.get(number)
            if register is None or op not in (Op.READ, Op.WRITE):
                self.malformed += 1      # an unknown register or op: no answer (hil's choice)
                return
            if op == Op.WRITE and register.writable:
                self._write(number, register.decode(data[4:8]))
            self.send(frame_on_bus(self.reply_id, data[:4] + register.encode(self._read(number)),
                             self.fd))

    def _write(self, number: int, value: float) -> None:
        """A register write the register can take (the module doc); a new CTRL_MODE zeroes
        the command of an enabled motor."""
        if not accepts(number, value, self.registers):
            return
        mode = self.control_mode
        self.registers[number] = int(value) & 0x7FF if number in ID_REGISTERS else value
        self._apply_registers()
        if self.control_mode is not mode and self.core.power is Power.ENABLED:
            self._zero_command()

    def _read(self, number: int) -> float:
        if number in (80, 81):           # p_m (the rotor's), xout (the output's)
            position = self.core.status().position - self.zero
            return position * self.registers[20] if number == 80 else position
        return self.registers[number]

    def _apply_registers(self) -> None:
        """What the registers mean to the motor now (the module doc), read once here rather
        than from the registers for every frame: every change to them comes through here."""
        registers = self.registers
        #: CTRL_MODE: which command id moves the motor
        self.control_mode = ControlMode(int(registers[10]))
        #: PMAX, VMAX, TMAX: the MIT commands' and every feedback's ranges
        self.ranges = MitRanges(registers[21], registers[22], KP_MAX, KD_MAX, registers[23])
        #: whether the motor answers in CAN FD (CAN_BR now: a write applies at once)
        self.fd = is_fd_code(registers[35])
        self.core.parameters = replace(self.core.parameters,
                                       watchdog_timeout=registers[9] * TIMEOUT_UNIT)

    # --- the simulator's side ----------------------------------------------------------

    def after_update(self) -> None:
        for fault in self.take_events():
            self.error = FAULT_STATES.get(fault, State.OVERLOAD)
            self.core.disable()          # the motor's output off, as it reports the error

    def restart(self) -> None:
        super().restart()
        self.registers = dict(self.saved)
        self.error = None
        self._apply_registers()

    def readings(self, frame: Frame) -> tuple[Reading, ...] | None:
        """Feedback: the motor id and state exact, position, velocity and torque."""
        data = frame.data
        if frame.identifier != self.reply_id or len(data) != 8 or is_register_answer(data):
            return None
        feedback = unpack_feedback(data, self.ranges)
        return (Reading("motor id", feedback.motor_id), Reading("state", feedback.state),
                *motion_readings(feedback))

    @property
    def state_text(self) -> str:
        return STATE_TEXT[self.state]


SPECIAL_FRAMES = {ENABLE: DamiaoDrive._enable, DISABLE: DamiaoDrive._disable,
                  SAVE_ZERO: DamiaoDrive._save_zero, CLEAR_ERROR: DamiaoDrive._clear_error}
COMMANDS = {ControlMode.MIT: DamiaoDrive._mit,
            ControlMode.POSITION_VELOCITY: DamiaoDrive._position_velocity,
            ControlMode.VELOCITY: DamiaoDrive._velocity,
            ControlMode.FORCE_POSITION: DamiaoDrive._force_position}
