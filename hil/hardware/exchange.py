"""The master's cycle on its buses: a cycle's frames out, its answers awaited.

Each cycle every axis gives its frames (:meth:`~hil.hardware.axis.Axis.cycle_frames`); a
bus' frames leave in one send, its protocols' cycle-end frames once after them
(:attr:`~hil.protocols.base.Protocol.cycle_end_frames`: CANopen's SYNC, which the drives
answer); then the answers are waited for, each axis marking its own
(:meth:`~hil.hardware.axis.Axis.answered`), and the cycle's round trip measured.
"""

from __future__ import annotations

import itertools
import math
import threading
import time
from contextlib import AbstractContextManager

import can

from hil.bus_config.types import SystemConfig
from hil.can import batches, held_together
from hil.can.frame import Frame
from hil.can.router import FrameRouter, start_router
from hil.hardware.axis import Axis, command_of
from hil.protocols import protocol
from hil.realtime import PeriodStatistics, Ring

#: answers an axis may miss in a row before it counts as silent
MISSED_ANSWER_LIMIT = 5
#: lock-step's wait for a cycle's answers (s): time stands still while nobody answers, so this
#: only has to tell a slow peer (a loaded machine, User-Mode Linux) from a dead one
LOCK_STEP_REPLY_TIMEOUT = 2.0


class CycleExchange:
    """The axes of a bus config's drives (one each, in config order, each of its protocol)
    and their frames on the buses: a cycle's out (:meth:`send`), its answers in
    (:meth:`await_answers`), the drives disabled at the end (:meth:`close`).

    A cycle's answers are due ``reply_timeout`` after its frames left (one period in real
    time): they travel while the loop sleeps, and a cycle's work does not wait for them."""

    def __init__(self, config: SystemConfig, buses: dict[str, can.BusABC],
                 reply_timeout: float):
        self.reply_timeout = reply_timeout
        self._buses = buses
        self._period = 1.0 / config.cycle_hz
        self.axes: list[Axis] = [protocol(drive.protocol).axis_class()(drive, bus.name,
                                                                       self._answered)
                                 for bus in config.buses for drive in bus.drives]
        self.routers: dict[str, FrameRouter] = {}
        self._configs = {bus.name: bus for bus in config.buses}
        #: per bus, what its protocols' master sends once after a cycle's frames
        self._cycle_end = {bus.name: list(bus.cycle_end_frames) for bus in config.buses
                           if bus.cycle_end_frames}
        self._batches: tuple[AbstractContextManager, ...] = ()
        #: cycles sent; the axes' answers carry the cycle they answer
        self.cycle = 0
        self._arrived = threading.Condition()
        self._awaiting = False          # a reader is in _await
        self._awaited: list[Axis] = []  # the axes it waits for
        #: each cycle's round trip (s): its frames handed to the buses to its last answer in
        self.round_trips = Ring(PeriodStatistics.KEEP)
        self._last_answer = 0.0
        self._sent: float | None = None     # perf_counter when the last cycle's frames went out

    def open(self) -> None:
        """A router on every bus, every axis on its bus' router."""
        for name, bus in self._buses.items():
            fd = self._configs[name].fd
            self.routers[name] = start_router(bus, classical=None if fd else name,
                                              describe=self._configs[name].frame_owner)
        self._batches = batches(self._buses.values())     # what send sends together
        for axis in self.axes:
            axis.attach(self.routers[axis.bus_name])

    # --- a cycle ----------------------------------------------------------------------

    def send(self, targets: list[float], speeds: list[float], torques: list[float],
             stopping: bool, holding: bool) -> None:
        """A new cycle: each axis' frames toward its target (motor units, :attr:`axes`
        order), a bus' frames in one send, its cycle-end frames last."""
        self.cycle += 1
        cycle = self.cycle
        # a bus' frames in one send (hil-virtual), the cycle-end frames after the frames they
        # end (CANopen's SYNC after its RPDOs, CiA 301 7.2.5); every bus' in one put where
        # they can (zenoh)
        on_bus: dict[str, list[Frame]] = {name: [] for name in self.routers}
        for axis, target, speed, torque in zip(self.axes, targets, speeds, torques):
            axis.begin_cycle(cycle)     # a torque only where the protocol carries one
            on_bus[axis.bus_name] += axis.cycle_frames(
                command_of((target, speed, torque, stopping, holding)))
        for name, frames in self._cycle_end.items():
            on_bus[name] += frames
        routers = self.routers
        # the time the frames are handed to the buses, not after: an answer may come (in
        # another thread) before the send returns, and its round trip was then negative
        self._sent = time.perf_counter()
        with held_together(self._batches):
            for name, frames in on_bus.items():
                routers[name].send_frames(frames)

    def await_answers(self, skip_silent: bool) -> float:
        """Wait until every axis' answer of the last cycle is in, or ``reply_timeout`` after
        its frames left; the cycle's round trip (s; NaN: not every answer came, or no cycle
        was sent), added to :attr:`round_trips`."""
        if self._sent is None:
            return math.nan
        if not self._await(skip_silent, self._sent + self.reply_timeout):
            return math.nan
        trip = self._last_answer - self._sent
        self.round_trips.add(trip)
        return trip

    def _await(self, skip_silent: bool, deadline: float) -> bool:
        """Wait (up to ``deadline``, perf_counter) until every axis' answer of this cycle is
        in; whether they all came.

        With ``skip_silent``, axes already past the missed-answer limit (reported silent) are
        not waited for while any other axis answers: in lock-step a dead drive would hold every
        cycle of the others for the whole timeout (2 s), and their stop with it."""
        cycle = self.cycle
        if not [a for a in self.axes if a.feedback.cycle != cycle]:   # not all() of a generator
            return True          # all in already (lock-step: in this thread), no wait
        awaited = self.axes
        if skip_silent:      # silent as of the last cycle's watch
            awaited = [a for a in self.axes if not missed_too_many(a, cycle - 1)] \
                or self.axes
        with self._arrived:
            self._awaited = awaited
            self._awaiting = True
            try:
                return self._arrived.wait_for(lambda: self._all_in(awaited),
                                              timeout=max(0.0, deadline - time.perf_counter()))
            finally:
                self._awaiting = False

    def _all_in(self, awaited: list[Axis]) -> bool:
        """Whether each of ``awaited`` has answered the current cycle."""
        cycle = self.cycle
        for axis in reversed(awaited):      # the last to answer first: the bus' order
            if axis.feedback.cycle != cycle:
                return False
        return True

    def _answered(self) -> None:
        """An axis' answer of the cycle is in (called in the thread that brought it)."""
        self._last_answer = time.perf_counter()
        # a reader sets the flag under the lock before it looks at the answers: an answer
        # that finds it unset was in before that look (no wake-up lost), and one that
        # arrives in the reader's own thread (lock-step) takes no lock. Only the answer that
        # completes the awaited set wakes the reader: a wake-up per answer cost the reader a
        # thread switch per drive (29 a cycle for a G1 across processes)
        if self._awaiting and self._all_in(self._awaited):
            with self._arrived:
                self._arrived.notify()

    # --- the end ----------------------------------------------------------------------

    def close(self) -> None:
        """Disable every drive (each in its protocol's way), then stop the routers (the
        buses stay open: their owner closes them)."""
        # each axis' rounds once (MIT's marks the motor as leaving motor mode), sent in step,
        # each round with the cycle-end frames its protocol acts on
        rounds = [[(axis.bus_name, frames) for frames in axis.disable_rounds()]
                  for axis in self.axes]
        for step in itertools.zip_longest(*rounds):
            for bus_name, frames in filter(None, step):
                self._send_quietly(bus_name, frames)
            for name, frames in self._cycle_end.items():
                self._send_quietly(name, frames)
            time.sleep(2 * self._period)
        for router in self.routers.values():
            router.stop(1.0)

    def _send_quietly(self, bus_name: str, frames: list[Frame]) -> None:
        """Each frame on its own: a bus that refuses one (it is going) still gets the
        others."""
        router = self.routers[bus_name]
        for frame in frames:
            try:
                router.send(frame)
            except can.CanError:
                pass


def missed_too_many(axis: Axis, cycle: int) -> bool:
    """Whether ``axis`` has missed more than MISSED_ANSWER_LIMIT answers by ``cycle``: the
    watch reports it silent, and the cycles after that do not wait for it."""
    return cycle - axis.feedback.cycle > MISSED_ANSWER_LIMIT
