"""The master's side of an ODrive axis on CANSimple (the protocol: :mod:`hil.protocols.odrive`).

Bring-up: Clear_Errors, a heartbeat requested by RTR (the axis is heard),
Set_Controller_Mode (position, passthrough) and Set_Limits, then
Set_Axis_State CLOSED_LOOP_CONTROL at standstill. Each cycle: Set_Input_Pos
(with velocity feed-forward), then RTRs for Get_Torques and
Get_Encoder_Estimates, whose answer is the cycle's feedback. The heartbeat
carries the axis state and errors; an error is reported with its name and
the disarm reason (Get_Error).
"""

from __future__ import annotations

import time

from hil.bus_config.types import DriveConfig
from hil.can.frame import Frame
from hil.can.router import Subscription
from hil.hardware.axis import Axis, AxisCommand, AxisFault, FaultKind
from hil.protocols.odrive import (
    LAYOUT, TURN, AxisState, Cmd, ControlMode, ODrive, ODriveError, ODriveOptions, can_id,
)

PASSTHROUGH = 1
#: Set_Input_Pos carries feed-forwards as int16 in units of 0.001
FF_SCALE = 1000
#: the layouts of each cycle's frames, looked up once
INPUT_POS, ESTIMATES, TORQUES = (LAYOUT[cmd] for cmd in (
    Cmd.SET_INPUT_POS, Cmd.GET_ENCODER_ESTIMATES, Cmd.GET_TORQUES))


class ODriveAxis(Axis):
    protocol = ODrive

    def __init__(self, config: DriveConfig, bus_name: str, on_feedback=lambda: None):
        super().__init__(config, bus_name, on_feedback)
        self.options: ODriveOptions = config.options or ODriveOptions()
        self.axis_state = AxisState.UNDEFINED
        self.axis_error = ODriveError.NONE
        self.disarm_reason = ODriveError.NONE
        self._requested_closed_loop = False
        self._pending: list[Frame] = []
        #: the requests of every cycle, and the heartbeat's while enabling: the same frames
        self._torques_request = self._request(Cmd.GET_TORQUES)
        self._estimates_request = self._request(Cmd.GET_ENCODER_ESTIMATES)
        self._heartbeat_request = self._request(Cmd.HEARTBEAT)
        self._input_pos_id = self._id(Cmd.SET_INPUT_POS)

    def _id(self, cmd: Cmd) -> int:
        return can_id(self.node_id, cmd)

    def _request(self, cmd: Cmd) -> Frame:
        """The RTR that asks for a Get_* message (or the heartbeat)."""
        return Frame(self._id(cmd), remote=True)

    def _command(self, cmd: Cmd, *values) -> Frame:
        return Frame(self._id(cmd), LAYOUT[cmd].pack(*values))

    def subscriptions(self) -> list[Subscription]:
        return [Subscription(self._id(Cmd.HEARTBEAT), self._on_heartbeat),
                Subscription(self._id(Cmd.GET_ENCODER_ESTIMATES), self._on_estimates),
                Subscription(self._id(Cmd.GET_TORQUES), self._on_torques),
                Subscription(self._id(Cmd.GET_ERROR), self._on_error)]

    def _on_heartbeat(self, frame: Frame) -> None:
        layout, data = LAYOUT[Cmd.HEARTBEAT], frame.data
        if len(data) < layout.size:
            return
        error, state, _, _ = layout.unpack_from(data)
        self.axis_error = ODriveError(error)
        self.axis_state = AxisState(state) if state in AxisState._value2member_map_ \
            else AxisState.UNDEFINED
        if state != AxisState.CLOSED_LOOP_CONTROL:
            self._requested_closed_loop = False
        if error and self.disarm_reason == ODriveError.NONE:
            self._pending.append(self._request(Cmd.GET_ERROR))
        self.booted.set()
        self.last_heard = time.monotonic()

    def _on_estimates(self, frame: Frame) -> None:
        data = frame.data
        if len(data) >= ESTIMATES.size:
            position, velocity = ESTIMATES.unpack_from(data)
            self.feedback.position, self.feedback.velocity = position * TURN, velocity * TURN
            self.answered()

    def _on_torques(self, frame: Frame) -> None:
        data = frame.data
        if len(data) >= TORQUES.size:
            self.feedback.torque = TORQUES.unpack_from(data)[1]

    def _on_error(self, frame: Frame) -> None:
        layout, data = LAYOUT[Cmd.GET_ERROR], frame.data
        if len(data) >= layout.size:
            active, reason = layout.unpack_from(data)
            self.disarm_reason = ODriveError(reason)

    # --- bring-up --------------------------------------------------------------------

    def reset(self) -> None:
        """Clear errors and ask for a heartbeat (the axis answers at once)."""
        super().reset()
        self.disarm_reason = ODriveError.NONE
        self._pending += [self._command(Cmd.CLEAR_ERRORS, 0), self._heartbeat_request]

    def configure(self) -> None:
        c = self.config
        self._pending += [
            self._command(Cmd.SET_CONTROLLER_MODE, ControlMode.POSITION_CONTROL, PASSTHROUGH),
            self._command(Cmd.SET_LIMITS, c.max_velocity / TURN,
                          c.peak_torque / self.options.torque_constant)]

    # --- cyclic ------------------------------------------------------------------------

    @property
    def state(self) -> str:
        errors = f" {self.axis_error!r}" if self.axis_error else ""
        return f"{self.axis_state.name}{errors}"

    @property
    def enabled(self) -> bool:
        return self.axis_state == AxisState.CLOSED_LOOP_CONTROL and not self.axis_error

    def cycle_frames(self, command: AxisCommand) -> list[Frame]:
        target, velocity, torque = command.target, command.velocity, command.torque
        stopping, enabling = command.stopping, command.holding
        frames, self._pending = self._pending, []
        if (not stopping and not self.axis_error and not self.enabled
                and not self._requested_closed_loop and self.at_standstill()
                and self.axis_state == AxisState.IDLE):
            self._requested_closed_loop = True
            frames.append(self._command(Cmd.SET_AXIS_STATE, AxisState.CLOSED_LOOP_CONTROL))
        if not self.enabled:
            frames.append(self._heartbeat_request)                    # watch it come up
        if stopping or enabling or not self.enabled:
            target, velocity = self.feedback.position, 0.0           # hold where it is
        if stopping or not self.enabled:
            torque = 0.0
        feed_forward = max(-32768, min(32767, round(velocity / TURN * FF_SCALE)))
        torque_ff = max(-32768, min(32767, round(torque * FF_SCALE)))
        frames += [
            Frame(self._input_pos_id, INPUT_POS.pack(target / TURN, feed_forward, torque_ff)),
            self._torques_request, self._estimates_request]
        return frames

    def disable_rounds(self) -> list[list[Frame]]:
        return [[self._command(Cmd.SET_AXIS_STATE, AxisState.IDLE)]]

    def fault(self, stopping: bool = False) -> AxisFault | None:
        if not self.axis_error:
            return None
        reason = (f", disarm reason {self.disarm_reason!r}"
                  if self.disarm_reason != ODriveError.NONE else "")
        return self.found(FaultKind.DISARMED, f"disarmed: {self.axis_error!r}{reason}",
                          int(self.axis_error))

    def forget_faults(self) -> None:
        self.axis_error = self.disarm_reason = ODriveError.NONE   # the next heartbeat tells
        self._pending.append(self._command(Cmd.CLEAR_ERRORS, 0))
