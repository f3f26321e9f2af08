"""The protocol-free core of a virtual servo drive: everything a servo drive does between
its CAN frames and its motor. The power stage (disabled with holding brake, enabled, quick
stop, fault), the position -> velocity -> torque cascade with feed-forward and anti-windup,
setpoint interpolation, torque and velocity saturation, following-error and position-limit
faults, the controller-silence watchdog with its configured reaction; the references it
follows are :mod:`hil.drives.references`'. A drive profile (CiA 402, ...) only
turns frames into calls on this class and its state into frames.

All quantities are on the motor side in SI units: rad, rad/s, N·m. The core is not
thread-safe; its owner serialises access.
"""

from __future__ import annotations

import math
from dataclasses import replace

from hil.drives.definitions import (
    DriveParameters, DriveStatus, Fault, Mode, Power, SilenceReaction, round_half_even,
)
from hil.drives.references import InterpolatedSetpoint, ProfileReference


class DriveCore:
    """One axis' drive electronics between setpoints and motor torque."""

    #: Encoder counts beyond the software position limits before a limit fault.
    LIMIT_MARGIN_COUNTS = 1000

    def __init__(self, parameters: DriveParameters):
        self.parameters = parameters
        self.power = Power.DISABLED
        self.mode = Mode.POSITION
        self.fault: Fault | None = None
        self.events: list[Fault] = []   # faults raised since the owner last drained them
        self.silence_reaction = SilenceReaction.QUICK_STOP
        self._silence_reported = False  # the watchdog fired; cleared by the next setpoint
        self._position = 0.0
        self._velocity = 0.0
        self._torque = 0.0
        self._integral = 0.0
        self._hold = 0.0                # position held by brake / quick stop
        self._setpoint = InterpolatedSetpoint()
        self._target_velocity = 0.0
        self._target_torque = 0.0
        self._velocity_ff = 0.0          # velocity offset: see new_setpoint
        #: position mode: the master gave a velocity feed-forward (CiA 402 0x60B1, ODrive's
        #: vel_ff) since the drive was enabled: it is the feed-forward, in place of the one
        #: the drive derives from the difference of its setpoints
        self._velocity_ff_given = False
        self._torque_ff = 0.0            # torque offset: see new_setpoint
        self._stiffness = 0.0            # impedance mode: kp (N·m/rad), kd (N·m·s/rad)
        self._damping = 0.0
        self._stop_velocity = 0.0
        self._following_time = 0.0
        self._following_error = 0.0
        self._internal_limit = False
        #: the last sign of life, forgotten on leaving ENABLED: the watchdog counts only while
        #: enabled (Ben Katz's mini-cheetah firmware, Hobbyking_Cheetah_Compact main.cpp: its
        #: counter runs in motor mode only; Damiao's DM-J zeroes its own while disarmed)
        self._last_setpoint: float | None = None
        # profile modes: the drive's own reference (position, velocity) and where it goes
        self._profile = ProfileReference()
        self._offset = 0.0              # the drive's position scale against the encoder's
        self._counts = 0                # the encoder's reading (counts, no offset)
        self._measured = False          # no position measured yet

    # --- commands from the profile ------------------------------------------

    def measure(self, position: float, velocity: float, dt: float = 0.0) -> None:
        """Latest motor position (quantised to encoder counts) and velocity: as given, or
        with ``velocity_filter`` the encoder's count difference over ``dt`` (the time since
        the last measurement), low-passed (backward Euler: v += (raw - v) dt / (T + dt))."""
        p = self.parameters
        step = p.radians_per_count
        self._position = round_half_even((position + self._offset) / step) * step
        counts = round_half_even(position / step)
        if p.velocity_filter > 0.0 and self._measured and dt > 0.0:
            raw = (counts - self._counts) * step / dt
            self._velocity += (raw - self._velocity) * dt / (p.velocity_filter + dt)
        else:
            self._velocity = velocity
        self._counts = counts
        if not self._measured:            # powered up: the brake holds where the axis is
            self._measured = True
            self._hold = self._position
            self._profile.hold(self._position)

    def enable(self) -> None:
        if self.power is Power.FAULT:
            return
        if self.power is not Power.ENABLED:
            self._integral = 0.0
            self._setpoint.hold(self._position)
            self._setpoint.elapsed = self._setpoint.cycle
            self._target_velocity = self._target_torque = 0.0
            self._velocity_ff = self._torque_ff = self._stiffness = self._damping = 0.0
            self._velocity_ff_given = False
            self._profile.hold(self._position)
        self.power = Power.ENABLED

    def disable(self) -> None:
        """Power off, brake on. The brake is anchored where it engaged: a repeated disable
        command does not move the anchor (re-anchoring at every command would let a
        loaded axis creep by the brake's sag each time)."""
        if self.power in (Power.ENABLED, Power.QUICK_STOP):
            self._engage_brake()
            self._last_setpoint = None      # the silence so far no longer counts
            self.power = Power.DISABLED

    def quick_stop(self) -> None:
        """Ramp to standstill at the quick-stop deceleration, then hold where it stopped."""
        if self.power is Power.ENABLED:
            self._stop_velocity = self._velocity
            self._hold = self._position       # a standing axis holds where it stands
            self._integral_from_torque()
            self._last_setpoint = None      # the silence so far no longer counts
            self.power = Power.QUICK_STOP

    def reset_fault(self) -> None:
        """FAULT -> DISABLED; the brake stays anchored where the fault engaged it."""
        if self.power is Power.FAULT:
            self.fault = None
            self.power = Power.DISABLED

    def set_mode(self, mode: Mode) -> None:
        if mode is not self.mode:
            self.mode = mode
            self._setpoint.hold(self._position)
            self._profile.hold(self._position)
            self._integral_from_torque()

    def hold_position(self) -> None:
        """Hold where the axis is now (profile modes: the reference starts here, at rest)."""
        self._setpoint.hold(self._position)
        self._profile.hold(self._position)

    def move_to(self, position: float) -> None:
        """Profile position mode: a new target; the move to it starts from where the drive's
        reference is now (a move in progress blends into it)."""
        self._profile.move_to(self._clamp_to_limits(position), self.parameters)

    def halt(self, halted: bool) -> None:
        """Profile modes: decelerate to standstill (and hold) while ``halted``; a halted
        move does not resume by itself."""
        if halted and not self._profile.halted:
            self._profile.target = math.nan      # the halted move is abandoned
        self._profile.halted = halted

    @property
    def move_done(self) -> bool:
        """Profile position mode: the reference has reached the target (or halted) and rests."""
        return self._profile.done

    @property
    def offset(self) -> float:
        """How far the drive's position scale is shifted from the encoder's (rad; homing)."""
        return self._offset

    def rebase(self, offset: float) -> None:
        """Shift the drive's own position scale by ``offset`` (homing): every stored position
        (limits, targets, references) moves with it, so nothing moves physically."""
        self._offset += offset
        self._position += offset
        self._hold += offset
        self._setpoint.start += offset
        self._setpoint.end += offset
        self._profile.shift(offset)
        limits = self.parameters.position_limits
        if limits is not None:
            self.parameters = replace(self.parameters,
                                      position_limits=(limits[0] + offset, limits[1] + offset))

    def set_cycle(self, cycle: float) -> None:
        """The control cycle (SYNC period) over which position targets are interpolated."""
        self._setpoint.cycle = cycle

    @property
    def cycle(self) -> float:
        """The interpolation period (s)."""
        return self._setpoint.cycle

    def new_setpoint(self, position: float | None = None, velocity: float | None = None,
                     torque: float | None = None, now: float | None = None, *,
                     velocity_ff: float | None = None, torque_ff: float | None = None,
                     stiffness: float | None = None, damping: float | None = None) -> None:
        """A cyclic setpoint: a position starts a new interpolation segment (position mode)
        or is the impedance target; ``velocity``/``torque`` are the velocity/torque mode
        targets, or the impedance mode's v_des and feed-forward torque. ``velocity_ff`` is,
        in position mode, the velocity feed-forward (in place of the setpoints' difference
        from then on), in velocity mode added to the target; ``torque_ff`` is added to the
        torque the loops command (position, velocity and torque modes), as CiA 402's velocity
        and torque offsets (0x60B1, 0x60B2) are."""
        if velocity_ff is not None:
            self._velocity_ff = velocity_ff
            self._velocity_ff_given = True
        if torque_ff is not None:
            self._torque_ff = torque_ff
        if stiffness is not None:
            self._stiffness = stiffness
        if damping is not None:
            self._damping = damping
        if position is not None:
            self._setpoint.new(self._clamp_to_limits(position))
        if velocity is not None:
            limit = self.parameters.max_velocity
            self._target_velocity = max(-limit, min(limit, velocity))
        if torque is not None:
            peak = self.parameters.peak_torque
            self._target_torque = max(-peak, min(peak, torque))
        if now is not None:
            self._last_setpoint = now
            self._silence_reported = False

    def check_watchdog(self, now: float) -> None:
        """Setpoints stopped arriving while enabled (wall-clock time): report it once and
        react as :attr:`silence_reaction` says."""
        timeout = self.parameters.watchdog_timeout
        if (timeout > 0 and self.power is Power.ENABLED and self._last_setpoint is not None
                and now - self._last_setpoint > timeout and not self._silence_reported):
            self._silence_reported = True
            self.lose_connection(Fault.CONTROLLER_SILENT)

    def lose_connection(self, cause: Fault | None = None) -> None:
        """The master is gone (silent, its heartbeat lost, or the network stopped): report
        ``cause`` (if any) and react as :attr:`silence_reaction` says."""
        reaction = self.silence_reaction
        if self.power is not Power.ENABLED:          # nothing follows the master now
            if cause is not None:
                self.events.append(cause)
            return
        if reaction is SilenceReaction.FAULT:
            self.raise_fault(cause if cause is not None else Fault.CONTROLLER_SILENT)
            return
        if cause is not None:
            self.events.append(cause)
        if reaction is SilenceReaction.QUICK_STOP:
            self.quick_stop()
        elif reaction is SilenceReaction.DISABLE:
            self.disable()

    def raise_fault(self, fault: Fault) -> None:
        if self.power is not Power.FAULT:
            self._engage_brake()
            self._last_setpoint = None      # the silence so far no longer counts
            self.power = Power.FAULT
            self.fault = fault
            self.events.append(fault)

    # --- the inner loops ----------------------------------------------------

    def update(self, dt: float) -> float:
        """Advance the inner loops by ``dt`` and return the motor torque command."""
        p = self.parameters
        self._check_position_limits()
        peak = p.peak_torque
        motor = True
        if self.power is Power.ENABLED:
            torque = self._enabled_torque(dt)
        elif self.power is Power.QUICK_STOP:
            torque = self._quick_stop_torque(dt)
        elif p.holding_brake:
            torque = self._brake_torque(dt)
            motor = False
        else:
            torque = 0.0
        if p.no_load_speed > 0.0 and motor and torque * self._velocity > 0.0:
            # driving (torque along the motion): the supply voltage less the back-EMF
            # leaves the motor this much; braking it has its full peak
            peak = peak * max(0.0, 1.0 - abs(self._velocity) / p.no_load_speed)
        self._torque = max(-peak, min(peak, torque))
        return self._torque

    def _enabled_torque(self, dt: float) -> float:
        p = self.parameters
        if self.mode is Mode.TORQUE:
            self._following_error = 0.0
            return self._target_torque + self._torque_ff
        if self.mode is Mode.VELOCITY:
            self._following_error = 0.0
            return (self._velocity_loop(self._target_velocity + self._velocity_ff, dt)
                    + self._torque_ff)
        if self.mode is Mode.IMPEDANCE:
            # no interpolation, no following-error check: the firmware of MIT motors has none
            self._following_error = self._setpoint.end - self._position
            return (self._stiffness * self._following_error
                    + self._damping * (self._target_velocity - self._velocity)
                    + self._target_torque)
        if self.mode is Mode.PROFILE_VELOCITY:
            self._following_error = 0.0
            self._profile.ramp(p, 0.0 if self._profile.halted else self._target_velocity, dt)
            return self._velocity_loop(self._profile.velocity, dt) + self._torque_ff
        if self.mode is Mode.PROFILE_POSITION or self.mode is Mode.HOMING:
            self._profile.step(p, dt)
            self._following_error = self._profile.position - self._position
            self._check_following_error(dt)
            velocity = self._profile.velocity + p.position_kp * self._following_error
            return self._velocity_loop(velocity, dt)
        self._setpoint.advance(dt)
        target = self._setpoint.target()
        feed_forward = self._velocity_ff if self._velocity_ff_given else self._setpoint.velocity()
        self._following_error = target - self._position
        self._check_following_error(dt)
        velocity = feed_forward + p.position_kp * self._following_error
        return self._velocity_loop(velocity, dt) + self._torque_ff

    def _quick_stop_torque(self, dt: float) -> float:
        p = self.parameters
        step = p.quick_stop_deceleration * dt
        if abs(self._stop_velocity) > step:
            self._stop_velocity -= math.copysign(step, self._stop_velocity)
            self._hold = self._position
            return self._velocity_loop(self._stop_velocity, dt)
        self._stop_velocity = 0.0
        return self._velocity_loop(p.position_kp * (self._hold - self._position), dt)

    def _brake_torque(self, dt: float) -> float:
        """A holding brake: a stiff position hold that slips above its torque."""
        p = self.parameters
        limit = p.brake_torque if p.brake_torque is not None else p.rated_torque
        velocity = p.position_kp * (self._hold - self._position)
        torque = self._velocity_loop(velocity, dt)
        return max(-limit, min(limit, torque))

    def _velocity_loop(self, velocity: float, dt: float) -> float:
        p = self.parameters
        velocity = max(-p.max_velocity, min(p.max_velocity, velocity))
        error = velocity - self._velocity
        proportional = p.velocity_kp * error
        integral = self._integral + p.velocity_ki * error * dt
        # anti-windup: the integral only holds what the torque limit leaves room for
        room = p.peak_torque - abs(proportional)
        integral = max(-room, min(room, integral)) if room > 0 else 0.0
        self._integral = integral
        return proportional + integral

    def _clamp_to_limits(self, position: float) -> float:
        limits = self.parameters.position_limits
        self._internal_limit = False
        if limits is None:
            return position
        clamped = max(limits[0], min(limits[1], position))
        self._internal_limit = clamped != position
        return clamped

    def _check_following_error(self, dt: float) -> None:
        p = self.parameters
        if p.following_error_limit <= 0 or abs(self._following_error) <= p.following_error_limit:
            self._following_time = 0.0
            return
        self._following_time += dt
        if self._following_time >= p.following_error_timeout:
            self.raise_fault(Fault.FOLLOWING_ERROR)

    def _check_position_limits(self) -> None:
        limits = self.parameters.position_limits
        if limits is None or self.power not in (Power.ENABLED, Power.QUICK_STOP):
            return
        # beyond a limit, moving further out faults; moving back in is allowed (an axis
        # enabled where gravity left it past its limit can be brought back)
        margin = self.LIMIT_MARGIN_COUNTS * self.parameters.radians_per_count
        creep = 0.01 * self.parameters.max_velocity
        if ((self._position < limits[0] - margin and self._velocity < -creep)
                or (self._position > limits[1] + margin and self._velocity > creep)):
            self.raise_fault(Fault.POSITION_LIMIT)

    def _engage_brake(self) -> None:
        self._hold = self._position
        self._integral = 0.0

    def _integral_from_torque(self) -> None:
        """Bumpless transfer: the integrator takes over the last torque."""
        self._integral = max(-self.parameters.peak_torque,
                             min(self.parameters.peak_torque, self._torque))

    # --- status ---------------------------------------------------------------

    def status(self) -> DriveStatus:
        p = self.parameters
        if self.mode is Mode.VELOCITY or self.mode is Mode.PROFILE_VELOCITY:
            target = 0.0 if self._profile.halted and self.mode is Mode.PROFILE_VELOCITY \
                else self._target_velocity
            reached = abs(self._velocity - target) < 0.01 * p.max_velocity
        elif self.mode is Mode.PROFILE_POSITION or self.mode is Mode.HOMING:
            profile = self._profile
            reached = self.move_done and (
                profile.halted or math.isnan(profile.target)
                or abs(profile.target - self._position) <= 10 * p.radians_per_count)
        else:
            reached = abs(self._setpoint.end - self._position) <= 10 * p.radians_per_count
        return DriveStatus(
            power=self.power, mode=self.mode, position=self._position, velocity=self._velocity,
            torque=self._torque, following_error=self._following_error,
            target_reached=reached and self.power is Power.ENABLED,
            internal_limit=self._internal_limit,
            following_error_exceeded=(p.following_error_limit > 0 and
                                      abs(self._following_error) > p.following_error_limit),
            stopped=self.power is Power.QUICK_STOP and self._stop_velocity == 0.0,
            fault=self.fault)
