"""Opening the CAN buses a bus config names (python-can), with command-line overrides."""

from __future__ import annotations

import logging

import can

from hil.bus_config.types import BusConfig, SystemConfig
from hil.can import WITHOUT_BIT_TIMING, open_bus
from hil.can.zenoh_receipts import AWAIT_MONITOR, wait_for_monitor
from hil.errors import HilError, UsageError
from hil.zenoh_session import ZenohSettings, session

log = logging.getLogger(__name__)


def open_buses(config: SystemConfig, zenoh: ZenohSettings, interface: str | None = None,
               channels: dict[str, str] | None = None, logging: bool = False,
               lossless: bool = False, await_monitor: bool = False) -> dict[str, can.BusABC]:
    """Open every bus of a config, with optional interface/channel overrides.

    Zenoh buses join the process' Zenoh session given by ``zenoh``; with ``logging`` (a
    monitor's) their frames are stamped with their senders' clock, the time they were on
    the bus; with ``lossless`` (a lock-step process') a send waits for room where a
    congested link would drop it; with ``await_monitor`` the buses are returned once a CAN
    monitor (``hil viz``) hears their frames, or AWAIT_MONITOR s have passed (then with a
    warning): its log holds the process' frames from the first.
    """
    channels = channels or {}
    unknown = set(channels) - {bus.name for bus in config.buses}
    if unknown:
        raise UsageError.single(f"--channel names unknown bus(es) {', '.join(sorted(unknown))}",
                                config.path,
                                hint=f"buses: {', '.join(bus.name for bus in config.buses)}")
    opened: dict[str, can.BusABC] = {}
    zenoh_buses = []
    try:
        for bus in config.buses:
            name = interface or bus.interface
            options = _fd_options(name, bus)
            if name == "zenoh":
                zenoh_buses.append(bus.name)
                options |= {"settings": zenoh, "timestamps": "sent" if logging else "arrival",
                            "lossless": lossless}
            opened[bus.name] = open_bus(name, channels.get(bus.name, bus.channel), bus.bitrate,
                                        **options)
    except HilError:
        for bus in opened.values():
            bus.shutdown()
        raise
    if await_monitor and zenoh_buses and not wait_for_monitor(session(zenoh)):
        log.warning("no CAN monitor joined bus(es) %s within %g s: a log begun later lacks "
                    "the frames sent before it", ", ".join(zenoh_buses), AWAIT_MONITOR)
    return opened


def _fd_options(interface: str, bus: BusConfig) -> dict:
    """python-can's FD options for one of hil's ends of ``bus``. SocketCAN's and hil's own
    ends take FD frames on every bus (a raw socket with CAN_RAW_FD_FRAMES, as candump opens
    one): on a classical bus a stray FD frame reaches the drives' router, which reports it
    and lets no device act on it. An interface with bit timing of its own (pcan, kvaser)
    is set up for FD where the bus is FD, its data phase at the bus' ``data_bitrate``."""
    if interface in WITHOUT_BIT_TIMING:
        return {"fd": True}
    if bus.fd:
        return {"fd": True, "data_bitrate": bus.data_bitrate}
    return {}
