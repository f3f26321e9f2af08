"""A drive's references, what its position loop follows: cyclic setpoints interpolated over
the control cycle (cyclic synchronous modes), and the drive's own trapezoidal moves and
velocity ramps in its profile modes (CiA 402's profile position and profile velocity modes).
Compiled with the drive core (setup.py)."""

from __future__ import annotations

import math

from hil.drives.definitions import DriveParameters


class InterpolatedSetpoint:
    """Cyclic position targets (rad, motor side), interpolated linearly from the last
    toward the latest over one control cycle (s), as a CSP drive does between SYNCs."""

    def __init__(self) -> None:
        self.start = 0.0           # the previous target, where the segment began
        self.end = 0.0             # the latest target
        self.elapsed = 0.0
        self.cycle = 1e-3

    def hold(self, position: float) -> None:
        """The reference stands at ``position``."""
        self.start = self.end = position

    def new(self, position: float) -> None:
        """A new target: the segment to it starts where the reference is now."""
        self.start = self.target()
        self.end = position
        self.elapsed = 0.0

    def advance(self, dt: float) -> None:
        self.elapsed = min(self.elapsed + dt, self.cycle)

    def target(self) -> float:
        """Where the reference is now."""
        if self.cycle <= 0 or self.elapsed >= self.cycle:
            return self.end
        fraction = self.elapsed / self.cycle
        return self.start + (self.end - self.start) * fraction

    def velocity(self) -> float:
        """The segment's velocity while it runs (0 once at its end)."""
        return (self.end - self.start) / self.cycle if self.elapsed < self.cycle else 0.0


class ProfileReference:
    """Where a profile move's reference is (rad, motor side), how fast it goes (rad/s),
    where it goes, and whether it is halted.

    A move is planned when its target is given (:meth:`move_to`), as a trapezoid from where
    the reference is, at its velocity, to the target: accelerate (or slow down) to the
    cruise speed, cruise, decelerate to rest on the target; a move too short to reach the
    cruise speed is a triangle. The plan is then followed in time, so a move takes exactly
    the time its limits imply (ODrive's TRAP_TRAJ; CiA 402's profile position mode with its
    linear ramp). A halt (or an abandoned move) ramps the velocity to 0 where it is.
    """

    def __init__(self) -> None:
        self.position = 0.0
        self.velocity = 0.0
        self.target = 0.0
        self.halted = False
        # the plan: from (start, speed0), signed rates and cruise speed, phase times
        self._start = 0.0
        self._speed0 = 0.0
        self._accel = 0.0
        self._decel = 0.0
        self._cruise = 0.0
        self._t_accel = 0.0
        self._t_cruise = 0.0
        self._t_total = 0.0
        self._elapsed = 0.0
        self._planned = False

    def hold(self, position: float) -> None:
        """Start from rest at ``position``."""
        self.position = self.target = position
        self.velocity = 0.0
        self.halted = False
        self._planned = False

    def move_to(self, target: float, p: DriveParameters) -> None:
        """Plan the move to ``target`` at the profile's limits (none: it does not start)."""
        self.target = target
        self.halted = False
        top = min(p.profile_velocity, p.max_velocity)
        accel, decel = p.profile_acceleration, p.profile_deceleration
        self._planned = top > 0 and accel > 0 and decel > 0
        if not self._planned:
            return
        distance = target - self.position
        speed0 = self.velocity
        stopping = math.copysign(speed0 * speed0 / (2.0 * decel), speed0)
        sign = 1.0 if distance - stopping >= 0.0 else -1.0
        cruise = sign * top
        # faster than cruising the right way (or going the wrong way): slow down first
        rate = sign * accel if sign * speed0 <= top else -sign * accel
        self._decel = -sign * decel
        t_accel = (cruise - speed0) / rate
        t_decel = -cruise / self._decel
        reach = 0.5 * t_accel * (cruise + speed0) + 0.5 * t_decel * cruise
        if sign * distance < sign * reach:                 # a triangle: no cruise
            peak_squared = (self._decel * speed0 * speed0 + 2 * rate * self._decel * distance) \
                / (self._decel - rate)
            cruise = sign * math.sqrt(max(peak_squared, 0.0))
            t_accel = max(0.0, (cruise - speed0) / rate)
            t_decel = max(0.0, -cruise / self._decel)
            t_cruise = 0.0
        else:
            t_cruise = (distance - reach) / cruise
        self._start, self._speed0, self._accel, self._cruise = self.position, speed0, rate, cruise
        self._t_accel, self._t_cruise = t_accel, t_cruise
        self._t_total = t_accel + t_cruise + t_decel
        self._elapsed = 0.0

    def shift(self, offset: float) -> None:
        """The drive's position scale moved by ``offset``: every position with it."""
        self.position += offset
        self.target += offset          # NaN stays NaN
        self._start += offset

    @property
    def done(self) -> bool:
        """Whether the reference is at rest: arrived, halted or its move abandoned."""
        return self.velocity == 0.0 and (
            self.halted or math.isnan(self.target) or self.position == self.target)

    def step(self, p: DriveParameters, dt: float) -> None:
        """Advance the reference by ``dt``: along the plan, or (halted, abandoned) to rest
        at the profile's deceleration."""
        if self.halted or math.isnan(self.target):
            self.ramp(p, 0.0, dt)
            self.position += self.velocity * dt
            return
        if not self._planned:
            return
        self._elapsed += dt
        t = self._elapsed
        if t < self._t_accel:
            self.position = self._start + self._speed0 * t + 0.5 * self._accel * t * t
            self.velocity = self._speed0 + self._accel * t
        elif t < self._t_accel + self._t_cruise:
            ta = self._t_accel
            self.position = (self._start + self._speed0 * ta + 0.5 * self._accel * ta * ta
                             + self._cruise * (t - ta))
            self.velocity = self._cruise
        elif t < self._t_total:
            left = t - self._t_total
            self.position = self.target + 0.5 * self._decel * left * left
            self.velocity = self._decel * left
        else:
            self.position, self.velocity = self.target, 0.0

    def ramp(self, p: DriveParameters, desired: float, dt: float) -> None:
        """Bring the velocity toward ``desired`` at the profile acceleration (speeding up)
        or deceleration (slowing down or reversing)."""
        desired = max(-p.max_velocity, min(p.max_velocity, desired))
        velocity = self.velocity
        speeding_up = desired * velocity >= 0.0 and abs(desired) > abs(velocity)
        step = (p.profile_acceleration if speeding_up else p.profile_deceleration) * dt
        if velocity < desired:
            self.velocity = min(desired, velocity + step)
        else:
            self.velocity = max(desired, velocity - step)
