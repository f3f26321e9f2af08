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
and a bench's ids are its config's). A write the register cannot take (CTRL_MODE outside
1-4, a range of 0, a value that is not a number) leaves it as it was, and the answer
carries the value it kept. The others are kept and read back as written. Saved values
(0xAA) survive a restart within the run (``hil sim --fault
restart:...``); unsaved ones are lost with it.
"""

from __future__ import annotations

import math
import struct
from contextlib import AbstractContextManager
from dataclasses import replace

from hil.drives.core import DriveCore
from hil.drives.definitions import Fault, Mode, Power, SilenceReaction
from hil.drives.profile import DriveProfile, Reading
from hil.protocols.damiao import (
    CLEAR_ERROR, DISABLE, ENABLE, SAVE_ZERO, ControlMode, Damiao, DamiaoOptions, Feedback, Op,
    REGISTER_ID, State, is_register_answer, pack_feedback, unpack_feedback,
)
from hil.protocols.damiao.registers import (
    AMBIENT, REGISTERS, TIMEOUT_UNIT, initial_values,
)
from hil.protocols.mit import MitRanges, unpack_command
from hil.protocols.mit.drive import enter_motor_mode, follow

#: the core's mode for each control mode
CORE_MODES = {ControlMode.MIT: Mode.IMPEDANCE, ControlMode.POSITION_VELOCITY:
              Mode.PROFILE_POSITION, ControlMode.VELOCITY: Mode.PROFILE_VELOCITY,
              ControlMode.FORCE_POSITION: Mode.PROFILE_POSITION}
#: core faults -> the state the motor reports (a following error, as ``hil sim --fault
#: fault:`` injects, is an overload to a motor that has no following-error check)
FAULT_STATES = {Fault.CONTROLLER_SILENT: State.LOST_COMMUNICATION}
#: ACC or DEC of 0: the reference steps at once (rad/s², finite: it multiplies distances)
NO_RAMP = 1e9
_FORCE_POSITION = struct.Struct("<fHH")
_TWO_FLOATS = struct.Struct("<ff")


class DamiaoDrive(DriveProfile):
    """One DM-J motor on a bus."""

    protocol = Damiao

    def __init__(self, node_id: int, core: DriveCore, lock: AbstractContextManager,
                 rated_torque: float, heartbeat_period: float = 0.1,
                 options: DamiaoOptions | None = None):
        super().__init__(node_id, core, lock)
        self.options = options or DamiaoOptions()
        ranges = self.options.ranges()
        self.registers = initial_values(self.options.model, node_id,
                                        self.options.reply_id(node_id),
                                        self.options.control_mode,
                                        core.parameters.watchdog_timeout)
        self.registers.update({21: ranges.p_max, 22: ranges.v_max, 23: ranges.t_max})
        self.saved = dict(self.registers)
        self.reply_id = self.options.reply_id(node_id)
        self.error: State | None = None
        self._zero = 0.0                 # motor position at "save zero"
        self._peak = core.parameters.peak_torque
        self._reply = b""
        core.silence_reaction = SilenceReaction.DISABLE
        self._apply_registers()

    # --- bus ----------------------------------------------------------------------------

    def subscriptions(self):
        handlers = {self.node_id + mode.id_offset: self._command_handler(mode)
                    for mode in ControlMode}
        handlers[REGISTER_ID] = self._on_register
        return handlers

    def _command_handler(self, mode: ControlMode):
        def receive(can_id: int, data: bytes, timestamp: float) -> None:
            if len(data) != 8:
                self.malformed += 1          # every command of the firmware is 8 bytes
                return
            with self.lock:
                self.heard()
                self._on_command_frame(mode, bytes(data))
                self._reply = self._feedback()
                self.on_command(self)
        return receive

    def _on_command_frame(self, mode: ControlMode, data: bytes) -> None:
        if mode is ControlMode.MIT and data in SPECIAL_FRAMES:
            SPECIAL_FRAMES[data](self)
        elif mode is self.control_mode and self.core.power is Power.ENABLED:
            COMMANDS[mode](self, data)
        # else: a command for another mode than CTRL_MODE's, or to a disabled motor: it
        # moves nothing, and the motor answers with its feedback (its state says why)

    def take_replies(self) -> list[tuple[int, bytes]]:
        reply, self._reply = self._reply, b""
        return [(self.reply_id, reply)] if reply else []

    @property
    def control_mode(self) -> ControlMode:
        return ControlMode(int(self.registers[10]))

    @property
    def ranges(self) -> MitRanges:
        return MitRanges(self.registers[21], self.registers[22], 500.0, 5.0, self.registers[23])

    def _feedback(self) -> bytes:
        status = self.core.status()
        return pack_feedback(Feedback(self.node_id, self.state, status.position - self._zero,
                                      status.velocity, status.torque, int(AMBIENT),
                                      int(AMBIENT)), self.ranges)

    @property
    def state(self) -> State:
        if self.error is not None:
            return self.error
        return State.ENABLED if self.core.power is Power.ENABLED else State.DISABLED

    # --- special frames ---------------------------------------------------------------

    def _enable(self) -> None:
        if self.error is not None:
            return                       # an error stands until it is cleared (FB)
        self.core.set_mode(CORE_MODES[self.control_mode])
        enter_motor_mode(self.core)
        self.core.hold_position()        # the modes other than MIT hold where they are

    def _disable(self) -> None:
        self.core.disable()

    def _save_zero(self) -> None:
        self._zero = self.core.status().position

    def _clear_error(self) -> None:
        self.error = None
        if self.core.power is Power.FAULT:
            self.core.reset_fault()

    # --- commands, one per control mode --------------------------------------------------

    def _mit(self, data: bytes) -> None:
        command = unpack_command(data, self.ranges)
        if self.core.parameters.peak_torque != self._peak:          # after force-position
            self.core.parameters = replace(self.core.parameters, peak_torque=self._peak)
        follow(self.core, command, self._zero)

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
            self.core.move_to(position + self._zero)

    def _profile(self, speed: float, torque_limit: float) -> None:
        self.core.parameters = replace(
            self.core.parameters, profile_velocity=speed, peak_torque=torque_limit,
            profile_acceleration=self.registers[4] or NO_RAMP,
            profile_deceleration=abs(self.registers[5]) or NO_RAMP)

    # --- registers -------------------------------------------------------------------

    def _on_register(self, can_id: int, data: bytes, timestamp: float) -> None:
        if len(data) != 8 or (data[0] | (data[1] << 8)) != self.node_id:
            return                       # another motor's, or not a request
        with self.lock:
            op, number = data[2], data[3]
            if op == Op.REFRESH:
                self.send(self.reply_id, self._feedback())
                return
            if op == Op.SAVE:
                self.saved = dict(self.registers)     # no answer: the sources show none
                return
            register = REGISTERS.get(number)
            if register is None or op not in (Op.READ, Op.WRITE):
                self.malformed += 1      # an unknown register or op: no answer (hil's choice)
                return
            if op == Op.WRITE and register.writable:
                value = register.decode(bytes(data[4:8]))
                if _acceptable(number, value):
                    self.registers[number] = value
                    self._apply_registers()
            self.send(self.reply_id, bytes(data[:4]) + register.encode(self._read(number)))

    def _read(self, number: int) -> float:
        if number in (80, 81):           # p_m (the rotor's), xout (the output's)
            position = self.core.status().position - self._zero
            return position * self.registers[20] if number == 80 else position
        return self.registers[number]

    def _apply_registers(self) -> None:
        """What the registers mean to the motor now (the module doc)."""
        self.core.parameters = replace(self.core.parameters,
                                       watchdog_timeout=self.registers[9] * TIMEOUT_UNIT)
        if self.core.power is Power.ENABLED and self.core.mode is not CORE_MODES[
                self.control_mode]:
            self.core.set_mode(CORE_MODES[self.control_mode])

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

    def readings(self, can_id: int, data: bytes) -> tuple[Reading, ...] | None:
        """Feedback: the motor id and state exact, position, velocity and torque."""
        if can_id != self.reply_id or len(data) != 8 or is_register_answer(data):
            return None
        feedback = unpack_feedback(data, self.ranges)
        return (Reading("motor id", feedback.motor_id), Reading("state", feedback.state),
                Reading("position", feedback.position, "position"),
                Reading("velocity", feedback.velocity, "velocity"),
                Reading("torque", feedback.torque, "torque"))

    @property
    def state_text(self) -> str:
        return self.state.name.replace("_", " ")


def _acceptable(number: int, value: float) -> bool:
    """Whether register ``number`` can take ``value``."""
    if not math.isfinite(value):
        return False
    if number == 10:
        return value in tuple(ControlMode)
    if number in (21, 22, 23):
        return value > 0
    return True


SPECIAL_FRAMES = {ENABLE: DamiaoDrive._enable, DISABLE: DamiaoDrive._disable,
                  SAVE_ZERO: DamiaoDrive._save_zero, CLEAR_ERROR: DamiaoDrive._clear_error}
COMMANDS = {ControlMode.MIT: DamiaoDrive._mit,
            ControlMode.POSITION_VELOCITY: DamiaoDrive._position_velocity,
            ControlMode.VELOCITY: DamiaoDrive._velocity,
            ControlMode.FORCE_POSITION: DamiaoDrive._force_position}
