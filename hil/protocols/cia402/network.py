"""python canopen's ``Network`` on hil's :class:`~hil.can.router.FrameRouter`: canopen's
services (the drive's SDO server, NMT slave and EMCY producer; the master's SDO client, PDO
maps and NMT master) hear and send through the bus' router, as every family's frames do.

canopen's ``Network`` is a frame dispatcher by COB-ID over a python-can bus; its own docs
name ``send_message`` and ``notify`` the points to override "to integrate this library with
a custom backend" (canopen 2.4 ``network.py``). Here :meth:`RoutedNetwork.subscribe` puts
each canopen callback (``callback(can_id, data: bytearray, timestamp)``, canopen's
``MessageListener`` form) on the router as a :class:`CanopenCallback`, and
:meth:`RoutedNetwork.send_message` sends a :class:`~hil.can.frame.Frame`. The per-cycle
frames (the drive's RPDOs, SYNC and TPDOs, the axis' PDOs) do not come this way: they are the
router's own handlers and frames (:mod:`.drive`, :mod:`.axis`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import canopen

from hil.can.frame import STANDARD_IDS, Frame
from hil.can.router import FrameRouter

#: what canopen calls a subscriber with: (COB-ID, data, timestamp)
Callback = Callable[[int, bytearray, float], None]


def extended_cob_id(can_id: int) -> bool:
    """Whether canopen sends (and hears) ``can_id`` as a 29-bit identifier: above 0x7FF, as
    canopen's own ``Network.send_message`` builds its messages (``is_extended_id=can_id >
    0x7FF``); its PDO maps keep a COB-ID without CiA 301's frame bit (bit 29)."""
    return can_id > STANDARD_IDS


@dataclass(frozen=True, slots=True)
class CanopenCallback:
    """A canopen subscriber as a router's handler: equal to another of the same callback, so
    that an unsubscribe finds it."""

    callback: Callback

    def __call__(self, frame: Frame) -> None:
        # a bytearray of its own, as canopen's MessageListener hands over a message's data
        self.callback(frame.identifier, bytearray(frame.data), frame.timestamp)


class RoutedNetwork(canopen.Network):
    """A canopen network whose frames go through ``router`` (module doc): one per drive or
    axis, on the router of its bus. It has no bus of its own (nothing bypasses the router)
    and no notifier (the router's delivery brings the frames)."""

    def __init__(self, router: FrameRouter):
        self.router = router
        super().__init__(None)
        # canopen's LSS master listens from the start; hil's nodes use none of it (the
        # simulated drive's LSS slave is hil's own, :mod:`.lss`)
        self.unsubscribe(self.lss.LSS_RX_COBID)

    def subscribe(self, can_id: int, callback: Callback) -> None:
        known = callback in self.subscribers.get(can_id, ())
        super().subscribe(can_id, callback)
        if not known:       # canopen subscribes a callback once
            self.router.subscribe(can_id, CanopenCallback(callback), extended_cob_id(can_id))

    def unsubscribe(self, can_id: int, callback: Callback | None = None) -> None:
        gone = list(self.subscribers.get(can_id, ())) if callback is None else [callback]
        super().unsubscribe(can_id, callback)    # canopen's error for one it does not have
        for each in gone:
            self.router.unsubscribe(can_id, CanopenCallback(each), extended_cob_id(can_id))

    def send_message(self, can_id: int, data: bytes, remote: bool = False) -> None:
        # canopen passes bytes, bytearrays and lists of ints: a Frame's data is bytes
        self.router.send(Frame(can_id, b"" if remote else bytes(data or b""),
                               extended_cob_id(can_id), remote=remote))
