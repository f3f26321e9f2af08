"""A bus config as typed objects: the bench (robot, plant rate, buses), each bus and each
drive. Drive quantities are motor side, SI units (rad, rad/s, N·m)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from hil.can import BusLoad, bus_load
from hil.description import RobotDescription
from hil.errors import Diagnostic
from hil.protocols import protocol

#: Bus load above which a bus has no room left for SDO, EMCY, heartbeats and retries.
LOAD_WARNING = 0.8
HEARTBEAT_PAYLOAD = 1
SYNC_PAYLOAD = 0


@dataclass(frozen=True)
class Gains:
    position_kp: float      # 1/s
    velocity_kp: float      # N·m·s/rad
    velocity_ki: float      # N·m/rad


@dataclass(frozen=True)
class DriveConfig:
    """One drive on a bus; ``gains`` None means tuned from the plant's inertia."""

    node_id: int
    actuator: str
    joints: tuple[str, ...]
    protocol: str
    encoder_counts_per_rev: int
    rated_torque: float
    peak_torque: float
    max_velocity: float
    following_error_limit: float
    following_error_timeout: float
    quick_stop_deceleration: float
    watchdog_timeout: float
    heartbeat_period: float
    holding_brake: bool
    position_limits: tuple[float, float] | None
    gains: Gains | None
    velocity_bandwidth_hz: float
    options: object | None = None     # the protocol's own settings (its profile's Options)
    line: int | None = None

    @property
    def label(self) -> str:
        return f"node {self.node_id} ({', '.join(self.joints)})"


@dataclass(frozen=True)
class BusConfig:
    name: str
    interface: str
    channel: str
    bitrate: int
    cycle_hz: float
    drives: tuple[DriveConfig, ...]
    line: int | None = None

    @property
    def cycle(self) -> float:
        return 1.0 / self.cycle_hz

    @property
    def uses_sync(self) -> bool:
        return any(protocol(d.protocol).uses_sync for d in self.drives)

    def frames(self, drive: DriveConfig) -> list[tuple[int, int, float]]:
        """(id, payload bytes, frames/s) of one drive's traffic, as its profile says."""
        return protocol(drive.protocol).bus_frames(drive.node_id, self.cycle_hz,
                                                   drive.heartbeat_period, drive.options)

    def load(self) -> BusLoad:
        """Worst-case traffic of every drive's cyclic exchange and timed messages (each
        profile's own frames and lengths), plus SYNC where a CANopen drive needs it."""
        streams = [(SYNC_PAYLOAD, self.cycle_hz)] if self.uses_sync else []
        for drive in self.drives:
            streams += [(payload, rate) for _, payload, rate in self.frames(drive) if rate > 0]
        return bus_load(self.bitrate, streams)


@dataclass(frozen=True)
class SystemConfig:
    """A whole bench: robot, plant rate, buses."""

    path: Path
    robot: RobotDescription
    plant_rate_hz: float
    buses: tuple[BusConfig, ...]
    warnings: tuple[Diagnostic, ...] = field(default=(), compare=False)

    @property
    def cycle_hz(self) -> float:
        return self.buses[0].cycle_hz

    @property
    def drives(self) -> tuple[DriveConfig, ...]:
        return tuple(d for bus in self.buses for d in bus.drives)

    @property
    def steps_per_cycle(self) -> int:
        return round(self.plant_rate_hz / self.cycle_hz)
