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
    where it goes, and whether it is halted."""

    def __init__(self) -> None:
        self.position = 0.0
        self.velocity = 0.0
        self.target = 0.0
        self.halted = False

    def hold(self, position: float) -> None:
        """Start from rest at ``position``."""
        self.position = self.target = position
        self.velocity = 0.0
        self.halted = False

    @property
    def done(self) -> bool:
        """Whether the reference is at rest: arrived, halted or its move abandoned."""
        return self.velocity == 0.0 and (
            self.halted or math.isnan(self.target) or self.position == self.target)

    def step(self, p: DriveParameters, dt: float) -> None:
        """Advance a trapezoidal move by ``dt``: toward the target at up to the profile
        velocity, accelerating and decelerating at the profile's rates, slowing so as to
        stop on the target (a halt or an abandoned move stops where it can)."""
        remaining = self.target - self.position
        if self.halted or math.isnan(remaining):
            desired = 0.0
        else:
            top = min(p.profile_velocity, p.max_velocity)
            stopping = math.sqrt(2.0 * max(p.profile_deceleration, 0.0) * abs(remaining))
            desired = math.copysign(min(top, stopping), remaining)
        self.ramp(p, desired, dt)
        step = self.velocity * dt
        if not math.isnan(remaining) and not self.halted and (
                remaining == 0.0 or (remaining - step) * remaining <= 0.0):
            self.position = self.target         # arrives (a step would overshoot)
            self.velocity = 0.0
        else:
            self.position += step

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
