"""One bus entry of a bus config: its name, interface, channel, bitrate, cycle rate and
drives, typed into a :class:`~hil.bus_config.types.BusConfig`."""

from __future__ import annotations

from hil.bus_config.drive_entry import read_drive
from hil.bus_config.types import BusConfig
from hil.bus_config.yaml_reader import LineMapping, Reader
from hil.description import RobotDescription
from hil.transmissions import Transmission
from hil.zenoh_session import key_name_problem

_BUS_KEYS = {"name", "interface", "channel", "bitrate", "cycle_hz", "drives"}


def read_bus(reader: Reader, raw, index: int, robot: RobotDescription,
             transmissions: tuple[Transmission, ...], defaults: LineMapping) -> BusConfig:
    bus = reader.mapping(raw, f"bus {index + 1}", None)
    reader.unknown_keys(bus, _BUS_KEYS, f"bus {index + 1}")
    name = reader.text(bus, "name", f"bus {index + 1}", f"bus{index + 1}")
    what = f"bus '{name}'"
    raw_drives = bus.get("drives")
    if not isinstance(raw_drives, list) or not raw_drives:
        reader.fail(f"{what}: 'drives' must be a non-empty list", bus.key_lines.get("drives",
                                                                                    bus.line))
        raw_drives = []
    drives = tuple(d for d in (read_drive(reader, raw_drive, what, robot, transmissions,
                                          defaults) for raw_drive in raw_drives) if d)
    return BusConfig(
        name=name,
        interface=reader.text(bus, "interface", what, "zenoh"),
        channel=_channel(reader, bus, what, f"{robot.name}/{name}"),
        bitrate=int(reader.number(bus, "bitrate", what, 1_000_000, integer=True)),
        cycle_hz=float(reader.number(bus, "cycle_hz", what)),
        drives=drives, line=bus.line)


def _channel(reader: Reader, bus: LineMapping, what: str, default: str) -> str:
    """The bus' channel: a key expression's chunks on the ``zenoh`` interface, so no
    wildcards (``hil/can/<channel>``)."""
    channel = reader.text(bus, "channel", what, default)
    problem = key_name_problem(channel, slashes=True)
    if problem:
        reader.fail(f"{what}: channel {channel!r}: {problem}",
                    bus.key_lines.get("channel", bus.line),
                    hint="e.g. channel: ur3/arm (or vcan0 for SocketCAN)")
    return channel
