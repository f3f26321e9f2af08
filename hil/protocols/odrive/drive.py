"""A simulated ODrive axis on CANSimple (the protocol: :mod:`hil.protocols.odrive`).

Errors as an ODrive reports them: a violated limit, an expired watchdog or an
estop disarms the axis (IDLE) with the error in ``active_errors`` and as the
``disarm_reason``, in every heartbeat, until ``Clear_Errors``.
"""

from __future__ import annotations

import math
import time
from contextlib import AbstractContextManager
from dataclasses import replace

from hil.drives.core import DriveCore
from hil.drives.definitions import Fault, Mode, Power
from hil.drives.profile import DriveProfile, Reading
from hil.protocols.odrive import (
    LAYOUT, TURN, AxisState, Cmd, ControlMode, ODrive, ODriveError, ODriveOptions, can_id,
)

CONTROL_MODES = {ControlMode.TORQUE_CONTROL: Mode.TORQUE,
                 ControlMode.VELOCITY_CONTROL: Mode.VELOCITY,
                 ControlMode.POSITION_CONTROL: Mode.POSITION}
#: core faults -> the ODrive error that disarms the axis
FAULT_ERRORS = {Fault.POSITION_LIMIT: ODriveError.POSITION_LIMIT_VIOLATION,
                Fault.CONTROLLER_SILENT: ODriveError.WATCHDOG_TIMER_EXPIRED,
                Fault.EMERGENCY_STOP: ODriveError.ESTOP_REQUESTED}
#: ODrive's vel_limit_tolerance: overspeed beyond this x the limit disarms
VELOCITY_TOLERANCE = 1.2
BUS_VOLTAGE = 24.0
FIRMWARE = (0, 6, 10)


class ODriveDrive(DriveProfile):
    """One ODrive axis on CANSimple, around a DriveCore.

    The cycle's command is the RTR for Get_Encoder_Estimates that a cyclic master
    sends after its setpoint; its answer is the cycle's reply.
    """

    protocol = ODrive

    def __init__(self, node_id: int, core: DriveCore, lock: AbstractContextManager,
                 rated_torque: float, heartbeat_period: float = 0.1,
                 options: ODriveOptions | None = None):
        super().__init__(node_id, core, lock)
        self.options = options or ODriveOptions()
        self.heartbeat_period = heartbeat_period
        self.axis_state = AxisState.IDLE
        self.active_errors = ODriveError.NONE
        self.disarm_reason = ODriveError.NONE
        self.control_mode = ControlMode.POSITION_CONTROL
        self.input_mode = 1                       # passthrough
        self.current_limit = core.parameters.peak_torque / self.options.torque_constant
        self._due: dict[Cmd, float] = {}
        self._reply = b""
        core.set_mode(Mode.POSITION)
        handlers = {Cmd.ESTOP: self._estop, Cmd.SET_AXIS_STATE: self._set_axis_state,
                    Cmd.SET_CONTROLLER_MODE: self._set_controller_mode,
                    Cmd.SET_INPUT_POS: self._set_input_pos, Cmd.SET_INPUT_VEL: self._set_input_vel,
                    Cmd.SET_INPUT_TORQUE: self._set_input_torque,
                    Cmd.SET_LIMITS: self._set_limits, Cmd.REBOOT: self._reboot,
                    Cmd.CLEAR_ERRORS: self._clear_errors}
        self._receivers = {can_id(node_id, cmd): self._receiver(cmd, handler)
                           for cmd, handler in handlers.items()}
        self._requests = {can_id(node_id, cmd): self._on_request for cmd in (
            Cmd.GET_VERSION, Cmd.HEARTBEAT, Cmd.GET_ERROR, Cmd.GET_ENCODER_ESTIMATES,
            Cmd.GET_IQ, Cmd.GET_TEMPERATURE, Cmd.GET_BUS_VOLTAGE_CURRENT, Cmd.GET_TORQUES,
            Cmd.GET_POWERS)}

    # --- bus ----------------------------------------------------------------------

    def subscriptions(self):
        return self._receivers

    def remote_subscriptions(self):
        return self._requests

    def attach(self, network) -> None:
        super().attach(network)
        self._due = {Cmd.HEARTBEAT: 0.0, **{cmd: 0.0 for cmd in self.options.rates()}}

    def _receiver(self, cmd: Cmd, handler):
        """A frame handler: check the length against the layout, take the lock, handle."""
        layout = LAYOUT.get(cmd)
        size = layout.size if layout is not None else 0

        def receive(arbitration_id: int, data: bytes, timestamp: float) -> None:
            if len(data) < size:
                self.malformed += 1           # the firmware drops short frames too
                return
            with self.lock:
                handler(layout.unpack_from(data) if layout is not None else ())
        return receive

    # --- commands -----------------------------------------------------------------

    def _estop(self, _) -> None:
        self.core.raise_fault(Fault.EMERGENCY_STOP)
        self._disarm(ODriveError.ESTOP_REQUESTED)

    def _set_axis_state(self, values) -> None:
        requested = values[0]
        if requested == AxisState.CLOSED_LOOP_CONTROL:
            if self.active_errors:
                self.disarm_reason = self.active_errors    # refused: the errors stand
                return
            self.core.set_mode(CONTROL_MODES.get(self.control_mode, Mode.POSITION))
            self.core.enable()
            self.axis_state = AxisState.CLOSED_LOOP_CONTROL
        elif requested == AxisState.IDLE:
            self.core.disable()
            self.axis_state = AxisState.IDLE

    def _set_controller_mode(self, values) -> None:
        control, self.input_mode = values
        if control in CONTROL_MODES:
            self.control_mode = ControlMode(control)
            self.core.set_mode(CONTROL_MODES[self.control_mode])

    def _set_input_pos(self, values) -> None:
        position, velocity_ff, torque_ff = values
        if math.isfinite(position):
            self.core.new_setpoint(position=position * TURN, now=time.monotonic(),
                                   velocity_ff=velocity_ff * 0.001 * TURN,
                                   torque_ff=torque_ff * 0.001)

    def _set_input_vel(self, values) -> None:
        velocity, torque_ff = values
        if math.isfinite(velocity) and math.isfinite(torque_ff):
            self.core.new_setpoint(velocity=velocity * TURN, torque_ff=torque_ff,
                                   now=time.monotonic())

    def _set_input_torque(self, values) -> None:
        if math.isfinite(values[0]):
            self.core.new_setpoint(torque=values[0], now=time.monotonic())

    def _set_limits(self, values) -> None:
        velocity_limit, current_limit = values
        if math.isfinite(velocity_limit) and velocity_limit > 0:
            self.core.parameters = replace(self.core.parameters,
                                           max_velocity=velocity_limit * TURN)
        if math.isfinite(current_limit) and current_limit > 0:
            self.current_limit = current_limit
            self.core.parameters = replace(
                self.core.parameters, peak_torque=current_limit * self.options.torque_constant)

    def _reboot(self, values) -> None:
        if values[0] == 0:                        # 1-3: save/erase config, DFU: not simulated
            self.core.disable()
            self.core.reset_fault()
            self.axis_state = AxisState.IDLE
            self.active_errors = self.disarm_reason = ODriveError.NONE

    def _clear_errors(self, _) -> None:
        self.core.reset_fault()
        self.active_errors = self.disarm_reason = ODriveError.NONE

    def _disarm(self, error: ODriveError) -> None:
        self.active_errors |= error
        self.disarm_reason = error
        self.axis_state = AxisState.IDLE
        if self.core.power is not Power.FAULT:
            self.core.raise_fault(Fault.CONTROLLER_SILENT if error is
                                  ODriveError.WATCHDOG_TIMER_EXPIRED else Fault.EMERGENCY_STOP)
        self.core.events.clear()

    # --- answers ------------------------------------------------------------------

    def _on_request(self, arbitration_id: int) -> None:
        cmd = Cmd(arbitration_id & 0x1F)
        with self.lock:
            data = self._payload(cmd)
            if cmd is Cmd.GET_ENCODER_ESTIMATES:
                self._reply = data
                self.on_command(self)
                return
        self.send(arbitration_id, data)

    def send_replies(self) -> None:
        reply, self._reply = self._reply, b""
        if reply:
            self.send(can_id(self.node_id, Cmd.GET_ENCODER_ESTIMATES), reply)

    def _payload(self, cmd: Cmd) -> bytes:
        """A Get_* message (or the heartbeat) with the axis' values now."""
        return LAYOUT[cmd].pack(*ANSWERS[cmd](self, self.core.status()))

    def after_update(self) -> None:
        events = self.take_events()
        for fault in events:
            self._disarm(FAULT_ERRORS[fault])
        status = self.core.status()
        limit = self.core.parameters.max_velocity
        if (self.core.power is Power.ENABLED
                and abs(status.velocity) > VELOCITY_TOLERANCE * limit):
            self._disarm(ODriveError.VELOCITY_LIMIT_VIOLATION)

    def tick(self, now: float) -> None:
        if not self.attached:
            return
        periods = {Cmd.HEARTBEAT: self.heartbeat_period, **self.options.rates()}
        for cmd, due in self._due.items():
            if now >= due:
                self._due[cmd] = max(due + periods[cmd], now)
                self.send(can_id(self.node_id, cmd), self._payload(cmd))

    # --- what a replay compares ---------------------------------------------------------

    def timed(self, can_id: int, data: bytes) -> bool:
        """The heartbeat and the messages sent at a configured rate (which also answer an
        RTR: a replay cannot tell the two apart, and checks neither frame by frame)."""
        cmd = can_id & 0x1F
        return cmd == Cmd.HEARTBEAT or cmd in self.options.rates()

    def timed_ids(self) -> tuple[int, ...]:
        return (can_id(self.node_id, Cmd.HEARTBEAT),)

    def timed_content(self, can_id: int) -> bytes | None:
        if can_id & 0x1F == Cmd.HEARTBEAT:
            return self._payload(Cmd.HEARTBEAT)
        return None

    def readings(self, can_id: int, data: bytes) -> tuple[Reading, ...] | None:
        """Encoder estimates in turns and turns/s, torques in N·m, the other Get_* values
        derived from them; None for what is exact (version, errors)."""
        cmd = can_id & 0x1F
        quantities = READINGS.get(cmd)
        if quantities is None or len(data) < LAYOUT[cmd].size:
            return None
        values = LAYOUT[cmd].unpack_from(data)
        return tuple(Reading(f"{Cmd(cmd).name.lower()}[{k}]", value, quantity, scale)
                     for k, (value, (quantity, scale)) in enumerate(zip(values, quantities)))

    @property
    def state_text(self) -> str:
        errors = f" {self.active_errors!r}" if self.active_errors else ""
        return f"{self.axis_state.name}{errors}"


def _power(status) -> float:
    return status.torque * status.velocity


#: what each Get_* message (and the heartbeat) carries: (drive, core status) -> values
ANSWERS = {
    Cmd.GET_VERSION: lambda drive, status: (2, 4, 0, 0, *FIRMWARE, 0),
    Cmd.HEARTBEAT: lambda drive, status: (int(drive.active_errors), int(drive.axis_state), 0,
                                          int(status.target_reached)),
    Cmd.GET_ERROR: lambda drive, status: (int(drive.active_errors), int(drive.disarm_reason)),
    Cmd.GET_ENCODER_ESTIMATES: lambda drive, status: (status.position / TURN,
                                                      status.velocity / TURN),
    Cmd.GET_IQ: lambda drive, status: (status.torque / drive.options.torque_constant,) * 2,
    Cmd.GET_TEMPERATURE: lambda drive, status: (35.0, 40.0),
    Cmd.GET_BUS_VOLTAGE_CURRENT: lambda drive, status: (BUS_VOLTAGE,
                                                        abs(_power(status)) / BUS_VOLTAGE),
    Cmd.GET_TORQUES: lambda drive, status: (status.torque, status.torque),
    Cmd.GET_POWERS: lambda drive, status: (abs(_power(status)), _power(status)),
}

#: how a replay reads the Get_* answers that carry measured values: (quantity, scale to SI)
#: per field (hil.drives.profile.Reading)
READINGS = {
    Cmd.GET_ENCODER_ESTIMATES: (("position", TURN), ("velocity", TURN)),
    Cmd.GET_TORQUES: (("torque", 1.0), ("torque", 1.0)),
    Cmd.GET_IQ: (("derived", 1.0), ("derived", 1.0)),
    Cmd.GET_BUS_VOLTAGE_CURRENT: ((None, 1.0), ("derived", 1.0)),
    Cmd.GET_POWERS: (("derived", 1.0), ("derived", 1.0)),
    Cmd.GET_TEMPERATURE: ((None, 1.0), (None, 1.0)),
}
