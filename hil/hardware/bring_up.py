"""The master's bring-up: every drive reset and waited for (retried, as a CiA 302 master
retries a slave's boot), configured, then enabled where it stands."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Mapping

import can
import numpy as np

from hil.errors import BootTimeout, BringUpError, EnableError
from hil.hardware.axis import Axis
from hil.hardware.exchange import CycleExchange
from hil.hardware.feedback import JointFeedback
from hil.hardware.hold_ups import not_enabled, slow_links, unreached_links
from hil.hardware.watch import FaultWatch

log = logging.getLogger(__name__)

#: how long a bring-up waits for every drive's boot-up by default (s): hil up starts the
#: controller once its sim runs; ``hil control`` alone waits longer (its --boot-timeout)
BOOT_TIMEOUT = 3.0
#: while waiting for drives, who is still missing is logged this often (s)
BOOT_REPORT_EVERY = 5.0
#: a drive not heard since its reset is reset again this often (s), as a CiA 302 master
#: retries a slave's boot: its boot-up may have been sent before the link to it was up
BOOT_RETRY_EVERY = 1.0
ENABLE_TIMEOUT = 10.0

#: one holding cycle of the master: hold the joints at these positions (write), then the
#: answers (read), its watch on or off
HoldingCycle = Callable[[np.ndarray, bool], JointFeedback]


class BringUp:
    """Brings the axes of ``exchange`` up, cycles running meanwhile (some protocols are
    heard only in answers): the axes reset and waited for up to ``boot_timeout`` (s; a
    CANopen master waits for its slaves' boot-up, CiA 302, whichever starts first), each
    configured, then all enabled (``ENABLE_TIMEOUT``). A silence or fault seen while
    enabling ends it with what it was."""

    def __init__(self, exchange: CycleExchange, watch: FaultWatch,
                 buses: Mapping[str, can.BusABC], boot_timeout: float):
        self._exchange = exchange
        self._watch = watch
        self._buses = buses
        self.boot_timeout = boot_timeout
        self.axes = exchange.axes

    def run(self, cycle: HoldingCycle, joints: int,
            cancel: threading.Event | None = None) -> JointFeedback:
        """The joints' feedback once every axis follows setpoints; ``cycle`` runs the master's
        holding cycles, ``cancel`` (set from another thread) ends the wait."""
        self._exchange.open()
        for axis in self.axes:                         # reset: every drive starts afresh
            axis.reset()
        hold = self._boot(cycle, np.zeros(joints), cancel)
        for axis in self.axes:
            self._watch.configure(axis)
        return self._enable(cycle, hold)

    def _boot(self, cycle: HoldingCycle, hold: np.ndarray,
              cancel: threading.Event | None) -> np.ndarray:
        """Cycles (unwatched) until every axis is heard; where they hold the joints."""
        began = time.monotonic()
        reported = retried = began
        while not all(axis.booted.is_set() for axis in self.axes):
            hold = cycle(hold, False).positions
            now = time.monotonic()
            silent = [a for a in self.axes if not a.booted.is_set()]
            labels = "; ".join(a.label for a in silent)
            if silent and now - began > self.boot_timeout:    # a cycle may outlast it
                raise BootTimeout.single(
                    f"{labels}: not heard within {self.boot_timeout:g} s after reset"
                    + unreached_links(self._buses),
                    hint="is `hil sim` (or the real drive) running on this bus, with the same "
                         "node id and protocol?", timeout=self.boot_timeout, **_where(silent))
            if cancel is not None and cancel.is_set():
                raise BringUpError.single(f"stopped while waiting for {labels} to boot",
                                          **_where(silent))
            if now - retried >= BOOT_RETRY_EVERY:
                retried = now
                for axis in self.axes:     # not silent's: one may have booted since
                    if not axis.booted.is_set():
                        axis.reset()
            if now - reported >= BOOT_REPORT_EVERY and silent:
                reported = now
                log.warning("waiting for %d of %d drive(s) to boot (%.0f of %g s): %s",
                            len(silent), len(self.axes), now - began, self.boot_timeout,
                            labels)
        return hold

    def _enable(self, cycle: HoldingCycle, hold: np.ndarray) -> JointFeedback:
        """Watched cycles until every axis is enabled; their last feedback."""
        deadline = time.monotonic() + ENABLE_TIMEOUT
        while True:
            feedback = cycle(hold, True)
            hold = feedback.positions
            waiting = [a for a in self.axes if not a.enabled]
            if not waiting:
                break
            faults = self._watch.queued() + [f for f in map(Axis.fault, waiting) if f]
            if faults or time.monotonic() > deadline:
                raise EnableError.single(
                    "drives did not enable: " + "; ".join(
                        [str(f) for f in faults] or [not_enabled(a) for a in waiting])
                    + slow_links(self._buses, self._exchange.reply_timeout),
                    **_where(waiting))
        self._watch.faults()          # what enabling found is over: the drives are enabled
        return feedback


def _where(axes: list[Axis]) -> dict:
    """The fields of a bring-up error about ``axes``: their labels, their bus where they
    share one, the node where there is one."""
    buses = {axis.bus_name for axis in axes}
    return {"drives": tuple(axis.label for axis in axes),
            "bus": next(iter(buses)) if len(buses) == 1 else None,
            "node": axes[0].node_id if len(axes) == 1 else None}
