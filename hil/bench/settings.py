"""What ``hil bench`` measures: robots, rates, run lengths."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

from hil.bus_config import SystemConfig
from hil.protocols.cia402 import Cia402, Cia402Options
from hil.resources import BUS_CONFIGS, data_dir

ROBOTS = ("ur3", "pigot")
#: the key of a real-time run's row whose stack did not start or run through, with why (every
#: attempt's reason): a host that cannot hold real time (a 2-vCPU VM's stalls) fails a
#: bring-up, and the bench reports it beside the runs that did start rather than losing them
DID_NOT_START = "did_not_start"
RATES = (250.0, 500.0, 1000.0)
#: the figures every report has (a row list, or {"unavailable": why})
FIGURES = ("control_cycle", "timing_floor", "socketcan", "lock_step", "overhead", "latency",
           "tracking", "bus_load", "fault_detection", "across_processes",
           "lock_step_across_processes", "scale")
#: across processes: (bus config, rate) pairs, each with and without the visualiser; the ur3
#: at 1 kHz on its three-bus config (two buses would carry 109 % of 1 Mbit/s at 1 kHz)
ACROSS_PROCESSES = (("ur3", 500.0), ("ur3_1khz", 1000.0), ("pigot", 500.0), ("pigot", 1000.0))
ACROSS_PROCESSES_QUICK = (("ur3", 500.0),)
#: scale: robots of this many drives (ur3 arms on one base), at these rates: 500 Hz on
#: classical buses, 1 kHz on CAN FD ones (hil.bench.scale; issue 69's two rates)
SCALE_DRIVES = (6, 12, 24, 34)
SCALE_RATES = (500.0, 1000.0)


@dataclass(frozen=True)
class BenchSettings:
    seconds: float = 10.0          # per real-time run
    lock_step_cycles: int = 20000
    bare_cycles: int = 5000
    config_dir: Path = field(default_factory=lambda: data_dir(BUS_CONFIGS))
    across_processes: tuple[tuple[str, float], ...] = ACROSS_PROCESSES
    scale_drives: tuple[int, ...] = SCALE_DRIVES
    scale_rates: tuple[float, ...] = SCALE_RATES

    @classmethod
    def quick(cls, config_dir: Path | None = None) -> BenchSettings:
        return cls(seconds=2.0, lock_step_cycles=600, bare_cycles=1000,
                   across_processes=ACROSS_PROCESSES_QUICK, scale_drives=(6, 12),
                   scale_rates=(500.0,),
                   **({"config_dir": config_dir} if config_dir else {}))



def with_rate(config: SystemConfig, rate: float) -> SystemConfig:
    """The same bench with every bus at ``rate`` Hz."""
    return replace(config, buses=tuple(replace(bus, cycle_hz=rate) for bus in config.buses))


def with_feed_forward(config: SystemConfig, gravity: bool = False) -> SystemConfig:
    """The same bench with every CiA 402 drive's master sending velocity feed-forward (ODrive
    and MIT masters always send theirs), and with ``gravity`` every master the torque that
    holds its joints against gravity too."""
    def fed(drive):
        if drive.protocol == Cia402.name:
            drive = replace(drive, options=Cia402Options("velocity"))
        return replace(drive, torque_feed_forward="gravity") if gravity else drive

    return replace(config, buses=tuple(replace(bus, drives=tuple(map(fed, bus.drives)))
                                       for bus in config.buses))
