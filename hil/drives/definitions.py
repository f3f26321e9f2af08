"""What a drive core is configured with and what it reports: its parameters, the power
stage's states, the operation modes, faults, the reaction to a silent master, and the
status of each cycle. Compiled with the core (setup.py)."""

from __future__ import annotations

import enum
import functools
import math
from dataclasses import dataclass


def round_half_even(value: float) -> int:
    """``round(value)`` of a float, to the same int (halves to the even one; NaN and the
    infinities raise as round does), for the compiled modules: there round() looks up the
    float's ``__round__`` and makes and frees a bound method at every call, many times a
    lock-step cycle (docs/performance.md, "2026-12-01: the in-process cycle in a fifth fewer
    instructions")."""
    whole = int(value)              # exact: the fraction's bits cleared (toward zero)
    fraction = value - whole        # exact too: the bits int() cleared
    if fraction > 0.5 or (fraction == 0.5 and whole & 1):
        return whole + 1
    if fraction < -0.5 or (fraction == -0.5 and whole & 1):
        return whole - 1
    return whole


class Power(enum.Enum):
    """What the power stage does."""

    DISABLED = "disabled"        # no torque; holding brake engaged if fitted
    ENABLED = "enabled"          # following targets in the active mode
    QUICK_STOP = "quick stop"    # ramping to standstill, then holding
    FAULT = "fault"              # disabled until the fault is reset


class Mode(enum.Enum):
    """What the enabled drive follows."""

    #: cyclic synchronous modes: a setpoint arrives every control cycle
    POSITION = "position"
    VELOCITY = "velocity"
    TORQUE = "torque"
    #: torque = kp (p - p_actual) + kd (v - v_actual) + torque feed-forward (MIT motors)
    IMPEDANCE = "impedance"
    #: the drive plans a trapezoidal move to each target (profile velocity, acceleration,
    #: deceleration) and follows it
    PROFILE_POSITION = "profile position"
    #: the target velocity, reached on a ramp of the profile acceleration/deceleration
    PROFILE_VELOCITY = "profile velocity"
    #: holding position while the profile sets its zero (homing on the current position)
    HOMING = "homing"


class SilenceReaction(enum.Enum):
    """What the drive does when its master goes silent or leaves it (CiA 402 0x6007,
    "abort connection option code")."""

    NONE = 0           # report it, carry on with the last setpoint
    FAULT = 1          # fault (brake on) until a fault reset
    DISABLE = 2        # disable voltage (brake on)
    QUICK_STOP = 3     # ramp to standstill, hold


class Fault(enum.Enum):
    """Drive faults, in the core's words: each protocol reports them in its own (an error
    code, an error bit, a state), as its drive profile maps them."""

    FOLLOWING_ERROR = "following error"
    POSITION_LIMIT = "position limit exceeded"
    CONTROLLER_SILENT = "setpoints stopped arriving (RPDO timeout)"
    HEARTBEAT_LOST = "the master's heartbeat stopped (heartbeat consumer)"
    EMERGENCY_STOP = "emergency stop requested"

    @property
    def text(self) -> str:
        return self.value


@dataclass(frozen=True)
class DriveParameters:
    """A drive's configuration, motor side, SI units."""

    counts_per_rev: int
    rated_torque: float
    peak_torque: float
    position_kp: float                 # 1/s
    velocity_kp: float                 # N·m·s/rad
    velocity_ki: float                 # N·m/rad
    max_velocity: float                # rad/s
    following_error_limit: float       # rad
    following_error_timeout: float     # s
    quick_stop_deceleration: float     # rad/s^2
    watchdog_timeout: float            # s; 0 disables the watchdog
    position_limits: tuple[float, float] | None = None
    holding_brake: bool = True
    brake_torque: float | None = None  # N·m; default: rated torque
    # profile modes (0: a profile move does not start)
    profile_velocity: float = 0.0      # rad/s
    profile_acceleration: float = 0.0  # rad/s^2
    profile_deceleration: float = 0.0  # rad/s^2
    #: the motor's torque-speed line (rad/s): driving, |torque| <= peak (1 - |w| / w0); 0: none
    no_load_speed: float = 0.0
    #: velocity from the encoder's counts through a first-order low-pass of this time
    #: constant (s); 0: the velocity measured as given (the plant's exact one)
    velocity_filter: float = 0.0

    @functools.cached_property    # read several times per drive and plant step
    def radians_per_count(self) -> float:
        return 2.0 * math.pi / self.counts_per_rev


@dataclass(init=False)
class DriveStatus:
    """What the drive reports each cycle (its profile encodes this)."""

    power: Power
    mode: Mode
    position: float
    velocity: float
    torque: float
    following_error: float
    target_reached: bool
    internal_limit: bool           # a target was clamped to the position limits
    following_error_exceeded: bool
    stopped: bool                  # quick stop has reached standstill
    fault: Fault | None

    # written out, not the dataclass' own: mypyc compiles this one, while the generated
    # __init__ runs interpreted (one per drive and SYNC; docs/performance.md, 2026-12-01)
    def __init__(self, power: Power, mode: Mode, position: float, velocity: float,
                 torque: float, following_error: float, target_reached: bool,
                 internal_limit: bool, following_error_exceeded: bool, stopped: bool,
                 fault: Fault | None) -> None:
        self.power, self.mode, self.position, self.velocity = power, mode, position, velocity
        self.torque, self.following_error = torque, following_error
        self.target_reached, self.internal_limit = target_reached, internal_limit
        self.following_error_exceeded, self.stopped, self.fault = (
            following_error_exceeded, stopped, fault)
