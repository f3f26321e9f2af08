"""What a bus can do beyond python-can's :class:`~can.BusABC`, declared with defaults.

python-can's BusABC declares its optional capabilities (``flush_tx_buffer``,
``_apply_filters``, ...) as methods with a default that does nothing, so that no caller asks
a bus what it is. hil's buses (``zenoh``, ``hil-virtual``, a bus with injected faults) offer
more: this class declares each of those the same way, and a bus that offers one overrides
it. A bus that is none of hil's (``socketcan``, python-can's ``virtual``, a vendor's
interface) offers none of them: :func:`capabilities` gives it these defaults.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from contextlib import AbstractContextManager, nullcontext
from typing import TYPE_CHECKING

import can

from hil.can.frame import Frame
from hil.realtime.stalls import Stall

if TYPE_CHECKING:
    from hil.can.delivery import DirectDelivery
    from hil.can.link_statistics import FrameCounters


#: the block of a bus that sends each frame as it is sent (nullcontext is re-entrant)
UNBATCHED = nullcontext()


class BusCapabilities:
    """The optional capabilities of a bus, each with the default of a bus without it."""

    #: what the bus sent, received and lost, and its link's round trip (None: it counts none)
    counters: FrameCounters | None = None

    def deliver_to(self, listeners: Iterable[can.Listener],
                   accept: Callable[[can.Message], can.Message | None] | None = None
                   ) -> DirectDelivery | None:
        """From now on give received frames to ``listeners`` in the thread that brings them
        (after ``accept``, which may change a frame or return None to drop it); None where
        the bus cannot (a Notifier then reads ``recv``)."""
        return None

    def frame_sender(self) -> Callable[[Sequence[Frame]], None] | None:
        """A function that sends :class:`~hil.can.frame.Frame` values, in order, building a
        ``can.Message`` only for receivers that want one; None where the bus sends messages
        only."""
        return None

    def batch(self) -> AbstractContextManager:
        """A block whose frames go out together (one message); by default each frame goes
        out as it is sent (:data:`UNBATCHED`)."""
        return UNBATCHED

    def deliver_under(self, guard: AbstractContextManager | None) -> None:
        """From now on deliver each batch of received frames inside ``guard``, entered once
        for them all; by default each frame is delivered on its own."""

    def watch_stalls(self, on_stall: Callable[[Stall], None] | None) -> None:
        """From now on call ``on_stall`` with each late delivery the bus measures; by
        default it measures none."""

    def unreached(self) -> str | None:
        """Why the bus reaches no other process, in words, where it can tell (None: it
        reaches someone, or cannot tell)."""
        return None


#: the capabilities of a bus that has none of them
NO_CAPABILITIES = BusCapabilities()


def capabilities(bus: can.BusABC) -> BusCapabilities:
    """``bus``'s optional capabilities: its own where it declares them, else the defaults."""
    return bus if isinstance(bus, BusCapabilities) else NO_CAPABILITIES
