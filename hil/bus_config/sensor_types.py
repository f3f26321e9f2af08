"""The sensors of a bus config, as typed objects (read by :mod:`.sensor_entry`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

Vector = tuple[float, float, float]
ZERO: Vector = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class TriadErrors:
    """The errors of one sensing triad (three alike axes: an accelerometer's or a gyroscope's),
    in SI units of its quantity (m/s² or rad/s). The terms of IEEE Std 952-1997, Annex C."""

    noise_density: float = 0.0        # white noise, unit/√Hz: Allan deviation N/√τ
    #: the flat floor of the Allan deviation is 0.664 · bias_instability (unit)
    bias_instability: float = 0.0
    #: the time the bias keeps its value (s): its Allan floor lies near 1.89 of it
    correlation_time: float = 100.0
    random_walk: float = 0.0          # rate random walk, unit/√s: Allan deviation K·√(τ/3)
    bias: Vector = ZERO               # turn-on bias of each axis (unit)
    scale_factor: Vector = ZERO       # each axis' gain error, a fraction (0.01: reads 1 % high)
    misalignment: Vector = ZERO       # the triad turned by these small angles about x, y, z (rad)


@dataclass(frozen=True)
class ImuConfig:
    """An IMU on a link of the robot, of a product family, on its wire."""

    name: str
    product: str                      # a name of hil.bus_config.sensor_entry.PRODUCTS
    link: str                         # the robot's link it is fixed to
    xyz: Vector                       # its place on the link (m)
    rpy: Vector                       # its axes on the link's (rad)
    rate_hz: float                    # samples a second
    outputs: tuple[int, ...]          # the product's packet types, in their order a sample
    latency: float                    # from sampling to the first byte on the wire (s)
    #: the angle (rad) one count of the orientation its reader takes stands for
    orientation_step: float
    accelerometer: TriadErrors
    gyroscope: TriadErrors
    seed: int = 0                     # of its noise: a run is the same run again
    line: int | None = None
    #: a serial sensor's: the link hil makes to its pseudo-terminal, and its baud rate
    port: Path | None = None
    baud: int | None = None
    #: a CAN sensor's: its bus (a bus of the config) and node id (a DM-IMU's CAN id)
    bus: str | None = None
    node_id: int | None = None
    #: a sensor that answers requests (the DM-IMU): the id it answers on, its firmware's
    #: version (hil.protocols.dm_imu.FIRMWARES) and how often hil control requests a sample
    master_id: int | None = None
    firmware: int | None = None
    poll_hz: float | None = None

    @property
    def period(self) -> float:
        return 1.0 / self.rate_hz



@dataclass(frozen=True)
class ForceTorqueConfig:
    """A six-axis force-torque sensor on a link of the robot, on its bus: it measures what
    the link takes from its parent (the load on a wrist sensor whose link is the hand: the
    hand's and what it holds), in its own axes."""

    name: str
    product: str                      # "ati_netft": ATI's Net F/T on CAN
    link: str
    xyz: Vector
    rpy: Vector
    bus: str
    base_id: int                      # the CAN base identifier (the Net F/T's DIP switches)
    counts_per_force: float           # its calibration: counts per N
    counts_per_torque: float          # counts per N·m
    short_divisors: tuple[float, float]   # long counts per short count: forces, torques
    force: TriadErrors                # N
    torque: TriadErrors               # N·m
    sample_hz: float                  # its internal rate: the noise's sample period
    poll_hz: float = 100.0            # how often hil control, its master, requests long data
    seed: int = 0
    line: int | None = None


#: every kind of sensor a bus config holds
Sensor = ImuConfig | ForceTorqueConfig
