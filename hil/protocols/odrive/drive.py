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
from contextlib import AbstractContextManager
from dataclasses import replace

from hil.bus_config.types import DriveConfig
from hil.can.frame import Frame, frame_of_fields
from hil.can.router import FrameRouter, Subscription
from hil.drives.core import DriveCore
from hil.drives.definitions import Fault, Mode, Power
from hil.drives.profile import DriveProfile, Reading
from hil.protocols.odrive import (
    BROADCAST_NODE_ID, LAYOUT, SERIAL_NUMBER_BASE, TURN, AxisState, Cmd, ControlMode, InputMode,
    ODrive, ODriveError, ODriveOptions, can_id,
)
from hil.protocols.odrive.answers import ANSWERS, READINGS
from hil.protocols.odrive.backed import backings
from hil.protocols.odrive.sdo import Address, EndpointServer

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
#: the firmware's command buffer: a shorter frame's missing bytes read as 0 (module doc)
BUFFER = 8
INPUT_POS = LAYOUT[Cmd.SET_INPUT_POS]


class ODriveDrive(DriveProfile):
    """One ODrive axis on CANSimple, around a DriveCore.

    The cycle's command is the RTR for Get_Encoder_Estimates that a cyclic master
    sends after its setpoint; its answer is the cycle's reply.
    """

    protocol = ODrive
    follows_every_step = True       # the velocity limit's check

    def __init__(self, config: DriveConfig, core: DriveCore, lock: AbstractContextManager):
        super().__init__(config, core, lock)
        node_id = config.node_id
        self.options: ODriveOptions = config.options or ODriveOptions()
        self.heartbeat_period = config.heartbeat_period
        self.axis_state = AxisState.IDLE
        self.active_errors = ODriveError.NONE
        self.disarm_reason = ODriveError.NONE
        self.control_mode = ControlMode.POSITION_CONTROL
        self.input_mode = 1                       # passthrough
        self.current_limit = core.parameters.peak_torque / self.options.torque_constant
        #: the timed messages' periods (s): the heartbeat's, the configured rates'
        self._periods = {Cmd.HEARTBEAT: self.heartbeat_period, **self.options.rates()}
        self._due: dict[Cmd, float] = {}
        self._reply: Frame | None = None
        self._estimates_id = can_id(node_id, Cmd.GET_ENCODER_ESTIMATES)
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
        file = self.options.endpoint_file
        self.hardware_version = file.hw_version if file else HARDWARE
        self.firmware_version = file.fw_version if file else FIRMWARE
        self.address = Address(node_id, self.options.serial_number
                               if self.options.serial_number is not None
                               else SERIAL_NUMBER_BASE + node_id)
        self._endpoints = EndpointServer(file, backings(self, handlers)) if file else None
        #: the Get_* message each request id asks for
        self._asked = {can_id(node_id, cmd): cmd for cmd in ANSWERS}
        self._subscriptions = self._subscribed(handlers)
        #: Set_Traj_* (turns/s, turns/s², N·m/(turns/s²)), gains as sent: the firmware's
        #: config values; TRAP_TRAJ moves at the limits
        self.traj_vel_limit, self.traj_accel_limit, self.traj_decel_limit = 2.0, 0.5, 0.5
        self.traj_inertia = 0.0
        self.pos_gain, self.vel_gain, self.vel_integrator_gain = 20.0, 0.16, 0.32

    # --- bus ----------------------------------------------------------------------

    def _subscribed(self, handlers) -> list[Subscription]:
        """Every frame the axis hears: its commands, discovery's Address frames (which every
        ODrive on the bus hears: the router calls each), RxSdo, and the Get_* requests, by
        RTR or by a data frame of length 0 (module doc)."""
        node_id = self.node_id
        subscriptions = [Subscription(can_id(node_id, cmd), self._receiver(cmd, handler))
                         for cmd, handler in handlers.items() if cmd is not Cmd.SET_INPUT_POS]
        subscriptions += [
            Subscription(can_id(node_id, Cmd.SET_INPUT_POS), self._on_input_pos),
            Subscription(ADDRESS_BROADCAST, self._on_address),
            Subscription(ADDRESS_BROADCAST, self._answer_address, remote=True),
            Subscription(can_id(node_id, Cmd.RX_SDO), self._on_rx_sdo)]
        subscriptions += [Subscription(identifier, self._on_estimates_request
                                       if cmd is Cmd.GET_ENCODER_ESTIMATES else self._on_request,
                                       remote=True) for identifier, cmd in self._asked.items()]
        if node_id != BROADCAST_NODE_ID:    # node 63's own Address id is the broadcast's
            subscriptions.append(Subscription(can_id(node_id, Cmd.ADDRESS), self._answer_address,
                                              remote=True))
        subscriptions += [Subscription(identifier, self._data_request)
                          for identifier, cmd in self._asked.items() if cmd is not Cmd.HEARTBEAT]
        return subscriptions

    def subscriptions(self) -> list[Subscription]:
        return list(self._subscriptions)

    def attach(self, router: FrameRouter) -> None:
        super().attach(router)
        self._due = {cmd: 0.0 for cmd in self._periods}

    # --- discovery and endpoints (hil.protocols.odrive.sdo) -------------------------

    def _answer_address(self, frame: Frame) -> None:
        """An Address RTR, broadcast or to this node: node id, serial, connection id."""
        with self.lock:
            payload = self.address.payload()
        self.send(Frame(can_id(self.node_id, Cmd.ADDRESS), payload))

    def _on_address(self, frame: Frame) -> None:
        """A set-address / connect frame on the broadcast id: this drive's when it names
        its serial number."""
        with self.lock:
            self.address.take(frame.data)

    def _on_rx_sdo(self, frame: Frame) -> None:
        """An endpoint read or write: answered from the endpoints file (none: silent), the
        watchdog fed as by every frame to the axis."""
        with self.lock:
            self.core.new_setpoint(now=self.clock())
            answer = self._endpoints.answer(frame.data) if self._endpoints else None
        if answer is not None:
            self.send(Frame(can_id(self.node_id, Cmd.TX_SDO), answer))

    def _receiver(self, cmd: Cmd, handler):
        """A command's frame handler: the frame's 8-byte buffer decoded by the layout (the
        module doc), the watchdog fed, under the lock."""
        layout = LAYOUT.get(cmd)

        def receive(frame: Frame) -> None:
            buffer = frame.data.ljust(BUFFER, b"\0")
            with self.lock:
                self.core.new_setpoint(now=self.clock())       # the watchdog's feed
                handler(layout.unpack_from(buffer) if layout is not None else ())
        return receive

    def _on_input_pos(self, frame: Frame) -> None:
        """Set_Input_Pos, a cyclic master's setpoint each cycle: decoded here, the watchdog
        fed by the setpoint's own core call (the receiver of the other commands makes two)."""
        data = frame.data
        values = INPUT_POS.unpack_from(data if len(data) >= BUFFER else data.ljust(BUFFER, b"\0"))
        with self.lock:
            self._set_input_pos(values, self.clock())

    def _data_request(self, frame: Frame) -> None:
        """A data frame on a Get_* id: of length 0, a request as an RTR is."""
        if not frame.data:
            if frame.identifier == self._estimates_id:
                self._on_estimates_request(frame)
            else:
                self._on_request(frame)

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

    def _set_input_pos(self, values, now: float | None = None) -> None:
        """Set_Input_Pos (or the ``input_pos`` endpoint): the watchdog fed ``now`` (None:
        the clock's now), in the setpoint's own core call where there is one."""
        position, velocity_ff, torque_ff = values
        core = self.core
        if now is None:
            now = self.clock()
        if math.isfinite(position) and core.mode is not Mode.PROFILE_POSITION:
            core.new_setpoint(position=position * TURN, now=now,
                              velocity_ff=velocity_ff * 0.001 * TURN, torque_ff=torque_ff * 0.001)
            return
        core.new_setpoint(now=now)
        if math.isfinite(position):                          # TRAP_TRAJ
            self._trajectory_limits()
            core.move_to(position * TURN)

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
                                   now=self.clock())

    def _set_input_torque(self, values) -> None:
        if math.isfinite(values[0]):
            self.core.new_setpoint(torque=values[0], now=self.clock())

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

    def _on_estimates_request(self, frame: Frame) -> None:
        """Get_Encoder_Estimates asked for: the cycle's command, its answer sampled now and
        sent with the bus' replies (:meth:`take_replies`)."""
        with self.lock:
            self.core.new_setpoint(now=self.clock())           # the watchdog's feed
            self._reply = frame_of_fields((self._estimates_id,
                                           self._payload(Cmd.GET_ENCODER_ESTIMATES),
                                           False, False, False, False, False, 0.0))
            self.on_command(self)

    def _on_request(self, frame: Frame) -> None:
        """Another Get_* message (or the heartbeat) asked for: answered at once."""
        identifier = frame.identifier
        with self.lock:
            self.core.new_setpoint(now=self.clock())           # the watchdog's feed
            data = self._payload(self._asked[identifier])
        self.send(frame_of_fields((identifier, data, False, False, False, False, False, 0.0)))

    def take_replies(self) -> list[Frame]:
        reply, self._reply = self._reply, None
        return [reply] if reply is not None else []

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
        for cmd, due in self._due.items():
            if now >= due:
                self._due[cmd] = max(due + self._periods[cmd], now)
                self.send(Frame(can_id(self.node_id, cmd), self._payload(cmd)))

    # --- what a replay compares ---------------------------------------------------------

    def timed(self, frame: Frame) -> bool:
        """The heartbeat and the messages sent at a configured rate (which also answer an
        RTR: a replay cannot tell the two apart, and checks neither frame by frame)."""
        return frame.identifier & 0x1F in self._periods

    def timed_ids(self) -> tuple[int, ...]:
        return (can_id(self.node_id, Cmd.HEARTBEAT),)

    def timed_content(self, identifier: int) -> bytes | None:
        if identifier & 0x1F == Cmd.HEARTBEAT:
            return self._payload(Cmd.HEARTBEAT)
        return None

    def readings(self, frame: Frame) -> tuple[Reading, ...] | None:
        """Encoder estimates in turns and turns/s, torques in N·m, the other Get_* values
        derived from them; None for what is exact (version, errors)."""
        cmd = frame.identifier & 0x1F
        quantities = READINGS.get(cmd)
        if quantities is None or len(frame.data) < LAYOUT[cmd].size:
            return None
        values = LAYOUT[cmd].unpack_from(frame.data)
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
