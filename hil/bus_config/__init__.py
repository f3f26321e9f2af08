"""Bus configs (``bus_config/*.yaml``): parsed once into typed objects.

A bus config names a robot description, the plant rate, and one or more CAN
buses, each with its python-can interface/channel, bitrate, cycle rate and
drives. Every problem is reported with the config file and line and what to
do, and the whole config is checked against the robot (joints, actuators,
node ids) and against the physics of the bus (worst-case load).

Drive quantities are motor side, SI units (rad, rad/s, N·m), as the drive
itself sees them.

The package: :mod:`~hil.bus_config.types` (the typed config), :mod:`~hil.bus_config.parse`
(YAML to types, every key checked with its line), :mod:`~hil.bus_config.checks` (the
config against its robot and the bus' physics), :mod:`~hil.bus_config.buses` (opening the
buses it names). The types import nothing heavy; ``load_bus_config`` and ``open_buses`` load
the parser and python-can's buses on first use.
"""

from hil.bus_config.types import LOAD_WARNING, BusConfig, DriveConfig, Gains, SystemConfig
from hil.lazy import lazy_exports

__getattr__ = lazy_exports(__name__, {"load_bus_config": "hil.bus_config.parse",
                                      "open_buses": "hil.bus_config.buses",
                                      "check_together": "hil.bus_config.checks",
                                      "config_path": "hil.bus_config.locate"})

__all__ = ["BusConfig", "DriveConfig", "Gains", "LOAD_WARNING", "SystemConfig",
           "check_together", "config_path", "load_bus_config", "open_buses"]
