"""CAN transports: every bus is a python-can bus, picked by interface name.

SocketCAN (``socketcan``, e.g. ``vcan0``) is the first-class target. Where a
kernel has no CAN, ``zenoh`` (this package's python-can plug-in) carries
frames across processes over loopback, and python-can's ``virtual`` works
inside one process (``hil-virtual``: the same, without a deep copy per frame).
"""

from __future__ import annotations

from hil.compiled import COMPILED_TRANSPORT, import_fresh

# compiled by the install where it could be (setup.py): the Zenoh transport's wire codec and
# link account and the router's dispatch, one build, loaded together before anything imports
# one of them
import_fresh(*COMPILED_TRANSPORT)

import errno  # noqa: E402
import socket  # noqa: E402
from collections.abc import Callable, Iterable  # noqa: E402
from contextlib import AbstractContextManager, ExitStack  # noqa: E402

import can  # noqa: E402

from hil.can.capabilities import UNBATCHED, BusCapabilities, capabilities  # noqa: E402
from hil.can.frames import BusLoad, bus_load, frame_bits  # noqa: E402
from hil.errors import BusError  # noqa: E402
from hil.realtime.stalls import Stall  # noqa: E402

__all__ = ["BusCapabilities", "BusLoad", "batches", "capabilities", "bus_load",
           "deliver_under", "frame_bits", "held_together", "link_round_trip", "link_unreached",
           "open_bus", "socketcan_missing", "watch_deliveries",
           "WITHOUT_BIT_TIMING"]


def batches(buses: Iterable[can.BusABC]) -> tuple[AbstractContextManager, ...]:
    """The blocks that hold these buses' frames for one message, one per Zenoh session
    (none for a bus that sends each frame as it is sent): asked once by a sender that sends
    on the same buses every cycle, which then asks no bus' capabilities every cycle."""
    return tuple(batch for batch in dict.fromkeys(capabilities(bus).batch() for bus in buses)
                 if batch is not UNBATCHED)


def held_together(blocks: tuple[AbstractContextManager, ...]) -> AbstractContextManager:
    """A block (``with held_together(blocks):``) inside all of ``blocks`` (:func:`batches`),
    each entered once: its frames go out together where the bus can do that (``zenoh``: one
    message for all the buses of a Zenoh session); others send each frame as it is sent."""
    if not blocks:              # no ExitStack a cycle where none batches (hil-virtual)
        return UNBATCHED
    if len(blocks) == 1:        # nor where one block holds them all (a Zenoh session's)
        return blocks[0]
    together = ExitStack()
    for block in blocks:
        together.enter_context(block)
    return together


def deliver_under(buses: Iterable[can.BusABC], guard: AbstractContextManager) -> None:
    """From now on the buses that deliver many frames at once (``zenoh``: a message) do so
    inside ``guard``, entered once for them all; others deliver each frame as ever."""
    for bus in buses:
        capabilities(bus).deliver_under(guard)


def watch_deliveries(buses: Iterable[can.BusABC], on_stall: Callable[[Stall], None]) -> None:
    """From now on ``on_stall`` gets each late delivery of the buses that time theirs
    (``zenoh``: it stamps its messages); others report none."""
    for bus in buses:
        capabilities(bus).watch_stalls(on_stall)


def link_round_trip(bus: can.BusABC) -> float | None:
    """The round trip (s) of the link under ``bus`` now (the least of its last few), for
    buses that measure it (``zenoh``: from the echoes of its messages), else None."""
    counters = capabilities(bus).counters
    return counters.round_trip_floor if counters is not None and counters.round_trips else None


def link_unreached(bus: can.BusABC) -> str | None:
    """Why the link under ``bus`` reaches no other process, for buses that can tell
    (``zenoh``: its session has no peer), else None."""
    return capabilities(bus).unreached()


def socketcan_missing(channels: tuple[str, ...] = ("vcan0",)) -> str | None:
    """None if every SocketCAN channel can be opened here, else why not."""
    if not hasattr(socket, "AF_CAN"):      # the platform's socket module, not a bus
        return "this Python has no AF_CAN"
    try:
        for channel in channels:
            with socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW) as probe:
                probe.bind((channel,))
    except OSError as exc:
        return f"no SocketCAN {'/'.join(channels)} here ({exc.strerror})"
    return None


#: python-can interfaces with no bit timing of their own to set (SocketCAN's is the link's,
#: set by ``ip link``; the virtual ones have none): they take no bit rates, and ``fd`` alone
#: says whether an end sends and receives FD frames
WITHOUT_BIT_TIMING = frozenset({"socketcan", "virtual", "hil-virtual", "zenoh"})


def open_bus(interface: str, channel: str, bitrate: int | None = None, **options) -> can.BusABC:
    """Open a python-can bus, turning the usual set-up failures into clear errors."""
    kwargs = dict(options)
    if bitrate and interface not in WITHOUT_BIT_TIMING:
        kwargs["bitrate"] = bitrate
    try:
        return can.Bus(interface=interface, channel=channel, **kwargs)
    except OSError as exc:
        raise _explain(interface, channel, exc) from None
    except (can.CanError, ValueError, ImportError) as exc:
        raise BusError.single(
            f"cannot open CAN bus '{channel}' with python-can interface '{interface}': {exc}",
            hint="check 'interface' and 'channel' in the bus config "
                 f"(python-can knows: {', '.join(sorted(can.VALID_INTERFACES))})") from None


def _explain(interface: str, channel: str, exc: OSError) -> BusError:
    if exc.errno == errno.EAFNOSUPPORT:
        return BusError.single(
            f"cannot open '{channel}': this kernel has no SocketCAN (AF_CAN)",
            hint="use interface 'zenoh' (cross-process over loopback), or run inside "
                 "User-Mode Linux with tools/uml_run.py, which has vcan")
    if exc.errno in (errno.ENODEV, errno.ENXIO):
        return BusError.single(
            f"CAN interface '{channel}' does not exist",
            hint=f"create it: sudo tools/vcan-setup.sh {channel}")
    return BusError.single(f"cannot open CAN bus '{channel}' ({interface}): {exc}")
