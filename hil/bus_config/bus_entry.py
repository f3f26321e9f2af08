"""One bus entry of a bus config: its name, interface, channel, bitrate, cycle rate and
drives, typed into a :class:`~hil.bus_config.types.BusConfig`."""

from __future__ import annotations

from dataclasses import replace

from hil.bus_config.drive_entry import read_drive
from hil.bus_config.types import BusConfig
from hil.bus_config.yaml_reader import LineMapping, Reader
from hil.description import RobotDescription
from hil.transmissions import Transmission
from hil.zenoh_session import key_name_problem

_BUS_KEYS = {"name", "interface", "channel", "bitrate", "fd", "data_bitrate", "cycle_hz",
             "drives"}
#: an FD bus' data phase when its entry names none: hil's choice, the rate LeRobot's Damiao
#: bus and Enactic's OpenArm set up (1 Mbit/s nominal, 5 Mbit/s data)
DEFAULT_DATA_BITRATE = 5_000_000


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
    bitrate = int(reader.number(bus, "bitrate", what, 1_000_000, integer=True))
    fd, data_bitrate = _fd(reader, bus, what, bitrate)
    drives = tuple(replace(d, can_fd=fd) for d in (
        read_drive(reader, raw_drive, what, robot, transmissions, defaults)
        for raw_drive in raw_drives) if d)
    return BusConfig(
        name=name,
        interface=reader.text(bus, "interface", what, "zenoh"),
        channel=_channel(reader, bus, what, f"{robot.name}/{name}"),
        bitrate=bitrate, cycle_hz=float(reader.number(bus, "cycle_hz", what)),
        drives=drives, line=bus.line, fd=fd, data_bitrate=data_bitrate)


def _fd(reader: Reader, bus: LineMapping, what: str, bitrate: int) -> tuple[bool, int | None]:
    """The bus' ``fd`` and its data phase's bit rate (None on a classical bus)."""
    fd = bus.get("fd", False)
    if not isinstance(fd, bool):
        reader.fail(f"{what}: fd must be true or false", bus.key_lines.get("fd", bus.line))
        fd = False
    if not fd:
        if "data_bitrate" in bus:
            reader.fail(f"{what}: data_bitrate is the data phase of CAN FD frames; this bus is "
                        "classical", bus.key_lines.get("data_bitrate", bus.line),
                        hint="add fd: true to the bus, or remove data_bitrate")
        return False, None
    data_bitrate = int(reader.number(bus, "data_bitrate", what, DEFAULT_DATA_BITRATE,
                                     integer=True))
    if data_bitrate < bitrate:
        # ISO 11898-1:2015: the data phase's bit time is at most the nominal one
        reader.fail(f"{what}: data_bitrate {data_bitrate} is below bitrate {bitrate}",
                    bus.key_lines.get("data_bitrate", bus.line),
                    hint="CAN FD's data phase runs at the nominal rate or faster "
                         "(e.g. bitrate: 1000000, data_bitrate: 5000000)")
    return True, data_bitrate


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
