"""What holds a bring-up back, in words for the error a master raises: a drive not enabled
yet, a link too slow for the cycle, a link that reaches nobody."""

from __future__ import annotations

from collections.abc import Mapping

import can

from hil.can import link_round_trip, link_unreached
from hil.hardware.axis import STANDSTILL, Axis


def not_enabled(axis: Axis) -> str:
    """Why ``axis`` is not enabled yet, in words: its state, and its motion where that is
    what holds it back (the master enables only at standstill)."""
    if axis.at_standstill() or not axis.feedback.heard:
        return f"{axis.label} is {axis.state}"
    return (f"{axis.label} is {axis.state}, never at standstill (moving at "
            f"{axis.feedback.velocity:.3g} rad/s on the motor, standstill below "
            f"{STANDSTILL * axis.config.max_velocity:.3g}): the joint is not held still")


def slow_links(buses: Mapping[str, can.BusABC], reply_timeout: float) -> str:
    """What the buses' links say, where a round trip outlasts the reply window (the drives'
    answers cannot come in their cycle over it): '' if none does."""
    slow = [(name, trip) for name, trip in ((n, link_round_trip(b)) for n, b in buses.items())
            if trip is not None and trip > reply_timeout]
    return "".join(f"; the link of bus '{name}' takes {trip * 1e3:.1f} ms a round trip, "
                   f"over the {reply_timeout * 1e3:.1f} ms the answers have: a slow "
                   "link (the network, or a Zenoh end falling behind), not the drives"
                   for name, trip in slow)


def unreached_links(buses: Mapping[str, can.BusABC]) -> str:
    """What the buses' links say, where one reaches no other process: '' if all do."""
    # buses of one process share a session: one reason, said once
    reasons = dict.fromkeys(why for why in map(link_unreached, buses.values()) if why)
    return "".join(f"; the link reaches nobody: {why}" for why in reasons)
