"""A simulated ODrive axis on CANSimple (the protocol: :mod:`hil.protocols.odrive`).

Errors as an ODrive reports them: a violated limit, an expired watchdog or an
estop disarms the axis (IDLE) with the error in ``active_errors`` and as the
``disarm_reason``, in every heartbeat, until ``Clear_Errors``.

Frames as the firmware takes them (ODrive's ``can_simple.cpp``, the open firmware's
``CANSimple::do_command``): every frame to the axis feeds its watchdog; a command is decoded
from the frame's 8-byte buffer whatever its length (a client's 1- or 4-byte Set_Axis_State
works: the bytes past the length read as 0 here, the hardware's are unspecified); a Get_*
message is requested by an RTR or by a data frame of length 0. Input modes: PASSTHROUGH
and TRAP_TRAJ (a trapezoidal move at the Set_Traj_* limits); the others (VEL_RAMP,
POS_FILTER, ...) are taken as PASSTHROUGH, which hil's docs say.
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
    BROADCAST_NODE_ID, BUS_VOLTAGE, LAYOUT, SERIAL_NUMBER_BASE, TURN, AxisState, Cmd,
    ControlMode, InputMode, ODrive, ODriveError, ODriveOptions, can_id,
)
from hil.protocols.odrive.backed import backings
from hil.protocols.odrive.sdo import Address, EndpointServer, Responders

CONTROL_MODES = {ControlMode.TORQUE_CONTROL: Mode.TORQUE,
                 ControlMode.VELOCITY_CONTROL: Mode.VELOCITY,
                 ControlMode.POSITION_CONTROL: Mode.POSITION}
#: core faults -> the ODrive error that disarms the axis
FAULT_ERRORS = {Fault.POSITION_LIMIT: ODriveError.POSITION_LIMIT_VIOLATION,
                Fault.CONTROLLER_SILENT: ODriveError.WATCHDOG_TIMER_EXPIRED,
                Fault.EMERGENCY_STOP: ODriveError.ESTOP_REQUESTED}
#: ODrive's vel_limit_tolerance: overspeed beyond this x the limit disarms
VELOCITY_TOLERANCE = 1.2
#: Get_Version without an endpoints file: hardware 4.0.0, firmware 0.6.10
HARDWARE, FIRMWARE = (4, 0, 0), (0, 6, 10)
#: the RTRs of discovery, on the unaddressed node's Address id (0x7E6)
ADDRESS_BROADCAST = can_id(BROADCAST_NODE_ID, Cmd.ADDRESS)


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
                    Cmd.CLEAR_ERRORS: self._clear_errors,
                    Cmd.SET_TRAJ_VEL_LIMIT: self._set_traj_vel_limit,
                    Cmd.SET_TRAJ_ACCEL_LIMITS: self._set_traj_accel_limits,
                    Cmd.SET_TRAJ_INERTIA: self._set_traj_inertia,
                    Cmd.SET_ABSOLUTE_POSITION: self._set_absolute_position,
                    Cmd.SET_POS_GAIN: self._set_pos_gain, Cmd.SET_VEL_GAINS: self._set_vel_gains}
        self._receivers = {can_id(node_id, cmd): self._receiver(cmd, handler)
                           for cmd, handler in handlers.items()}
        self._receivers[ADDRESS_BROADCAST] = self._on_address
        file = self.options.endpoint_file
        self.hardware_version = file.hw_version if file else HARDWARE
        self.firmware_version = file.fw_version if file else FIRMWARE
        self.address = Address(node_id, self.options.serial_number
                               if self.options.serial_number is not None
                               else SERIAL_NUMBER_BASE + node_id)
        self._endpoints = EndpointServer(file, backings(self, handlers)) if file else None
        self._receivers[can_id(node_id, Cmd.RX_SDO)] = self._on_rx_sdo
        self._requests = {can_id(node_id, cmd): self._on_request for cmd in ANSWERS}
        if node_id != BROADCAST_NODE_ID:    # node 63's own Address id is the broadcast's
            self._requests[can_id(node_id, Cmd.ADDRESS)] = self._answer_address
        self._receivers.update({can_id(node_id, cmd): self._data_request for cmd in ANSWERS
                                if cmd is not Cmd.HEARTBEAT})
        #: Set_Traj_* (turns/s, turns/s², N·m/(turns/s²)), gains as sent: the firmware's
        #: config values; TRAP_TRAJ moves at the limits
        self.traj_vel_limit, self.traj_accel_limit, self.traj_decel_limit = 2.0, 0.5, 0.5
        self.traj_inertia = 0.0
        self.pos_gain, self.vel_gain, self.vel_integrator_gain = 20.0, 0.16, 0.32

    # --- bus ----------------------------------------------------------------------

    def subscriptions(self):
        return self._receivers

    def remote_subscriptions(self):
        return self._requests

    def attach(self, network) -> None:
        super().attach(network)
        Responders.of(network.frame_listener.remote_handlers, ADDRESS_BROADCAST).join(
            self._answer_address)
        self._due = {Cmd.HEARTBEAT: 0.0, **{cmd: 0.0 for cmd in self.options.rates()}}

    def detach(self) -> None:
        if self.network is not None:
            Responders.of(self.network.frame_listener.remote_handlers,
                          ADDRESS_BROADCAST).leave(self._answer_address)
        super().detach()

    # --- discovery and endpoints (hil.protocols.odrive.sdo) -------------------------

    def _answer_address(self, arbitration_id: int) -> None:
        """An Address RTR, broadcast or to this node: node id, serial, connection id."""
        with self.lock:
            payload = self.address.payload()
        self.send(can_id(self.node_id, Cmd.ADDRESS), payload)

    def _on_address(self, arbitration_id: int, data: bytes, timestamp: float) -> None:
        """A set-address / connect frame on the broadcast id: this drive's when it names
        its serial number."""
        with self.lock:
            self.address.take(bytes(data))

    def _on_rx_sdo(self, arbitration_id: int, data: bytes, timestamp: float) -> None:
        """An endpoint read or write: answered from the endpoints file (none: silent), the
        watchdog fed as by every frame to the axis."""
        with self.lock:
            self.core.new_setpoint(now=time.monotonic())
            answer = self._endpoints.answer(bytes(data)) if self._endpoints else None
        if answer is not None:
            self.send(can_id(self.node_id, Cmd.TX_SDO), answer)

    def _receiver(self, cmd: Cmd, handler):
        """A frame handler: the frame's 8-byte buffer decoded by the layout (the module
        doc), the watchdog fed, under the lock."""
        layout = LAYOUT.get(cmd)

        def receive(arbitration_id: int, data: bytes, timestamp: float) -> None:
            buffer = bytes(data).ljust(8, b"\0")
            with self.lock:
                self.core.new_setpoint(now=time.monotonic())       # the watchdog's feed
                handler(layout.unpack_from(buffer) if layout is not None else ())
        return receive

    def _data_request(self, arbitration_id: int, data: bytes, timestamp: float) -> None:
        """A data frame on a Get_* id: of length 0, a request as an RTR is."""
        if len(data) == 0:
            self._on_request(arbitration_id)

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
            self.core.set_mode(self._core_mode())
            self.core.enable()
            self.axis_state = AxisState.CLOSED_LOOP_CONTROL
        elif requested == AxisState.IDLE:
            self.core.disable()
            self.axis_state = AxisState.IDLE

    def _set_controller_mode(self, values) -> None:
        control, self.input_mode = values
        if control in CONTROL_MODES:
            self.control_mode = ControlMode(control)
            self.core.set_mode(self._core_mode())

    def _core_mode(self) -> Mode:
        if self.control_mode is ControlMode.POSITION_CONTROL \
                and self.input_mode == InputMode.TRAP_TRAJ:
            return Mode.PROFILE_POSITION
        return CONTROL_MODES.get(self.control_mode, Mode.POSITION)

    def _set_input_pos(self, values) -> None:
        position, velocity_ff, torque_ff = values
        if not math.isfinite(position):
            return
        if self.core.mode is Mode.PROFILE_POSITION:          # TRAP_TRAJ
            self._trajectory_limits()
            self.core.move_to(position * TURN)
        else:
            self.core.new_setpoint(position=position * TURN, now=time.monotonic(),
                                   velocity_ff=velocity_ff * 0.001 * TURN,
                                   torque_ff=torque_ff * 0.001)

    def _trajectory_limits(self) -> None:
        self.core.parameters = replace(
            self.core.parameters, profile_velocity=self.traj_vel_limit * TURN,
            profile_acceleration=self.traj_accel_limit * TURN,
            profile_deceleration=self.traj_decel_limit * TURN)

    def _set_traj_vel_limit(self, values) -> None:
        if math.isfinite(values[0]) and values[0] >= 0:
            self.traj_vel_limit = values[0]

    def _set_traj_accel_limits(self, values) -> None:
        if all(math.isfinite(v) and v > 0 for v in values):
            self.traj_accel_limit, self.traj_decel_limit = values

    def _set_traj_inertia(self, values) -> None:
        if math.isfinite(values[0]):
            self.traj_inertia = values[0]

    def _set_absolute_position(self, values) -> None:
        """The position estimate becomes the value (turns); nothing moves."""
        if math.isfinite(values[0]):
            self.core.rebase(values[0] * TURN - self.core.status().position)

    def _set_pos_gain(self, values) -> None:
        if math.isfinite(values[0]):
            self.pos_gain = values[0]

    def _set_vel_gains(self, values) -> None:
        if all(math.isfinite(v) for v in values):
            self.vel_gain, self.vel_integrator_gain = values

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
            self.core.new_setpoint(now=time.monotonic())           # the watchdog's feed
            data = self._payload(cmd)
            if cmd is Cmd.GET_ENCODER_ESTIMATES:
                self._reply = data
                self.on_command(self)
                return
        self.send(arbitration_id, data)

    def take_replies(self) -> list[tuple[int, bytes]]:
        reply, self._reply = self._reply, b""
        return [(can_id(self.node_id, Cmd.GET_ENCODER_ESTIMATES), reply)] if reply else []

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

    def trajectory_done(self, status) -> bool:
        """The heartbeat's Trajectory_Done_Flag: in TRAP_TRAJ, the trajectory has reached
        its end (not the axis: the firmware's trap_traj_.done_); else the target reached."""
        if self.core.mode is Mode.PROFILE_POSITION:
            return self.core.move_done
        return status.target_reached

    @property
    def state_text(self) -> str:
        errors = f" {self.active_errors!r}" if self.active_errors else ""
        return f"{self.axis_state.name}{errors}"


def _power(status) -> float:
    return status.torque * status.velocity


#: what each Get_* message (and the heartbeat) carries: (drive, core status) -> values
ANSWERS = {
    Cmd.GET_VERSION: lambda drive, status: (2, *drive.hardware_version,
                                            *drive.firmware_version, 0),
    Cmd.HEARTBEAT: lambda drive, status: (int(drive.active_errors), int(drive.axis_state), 0,
                                          int(drive.trajectory_done(status))),
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
