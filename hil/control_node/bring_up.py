"""The controller's real-time bring-up judged against the bench's own stalls.

A drive found silent while the bench stalled is the bench's fault in the cycles
(:mod:`hil.control_node.attribution`); the bring-up's waits (a drive's boot, an SDO answer,
the enable) fail the same way when the simulator, the transport or the controller itself
does not run. Such a failure stays a failure, the drives are not brought up, but it is told
as the bench's, with the stalls that explain it and :data:`BENCH_STALL_STATUS`.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from typing import TypeVar

from hil.control_node.attribution import GRACE, stalls_in_words
from hil.errors import BringUpError, HilError, error
from hil.realtime.stalls import BENCH_STALL_STATUS, Stall, StallWatch

#: a stall this long during the bring-up can fail it (s). hil's own choice (no maker's
#: document speaks of a bench's stalls): five cycles at 100 Hz, the slowest rate hil runs, is
#: the silence limit that ends a bring-up soonest; canopen waits 0.3 s for an SDO answer
BRING_UP_STALL = 0.05
#: how often the reports of stalls are looked at while waiting for them (s)
_POLL = 0.05

Feedback = TypeVar("Feedback")


class BringUpStalled(BringUpError):
    """A bring-up that failed while the bench itself stalled: the failure's diagnostics
    (their hints left out: they send the user to the drive), then the stalls. A bring-up
    error still (the drives were not brought up), about the failure's drives."""

    exit_status = BENCH_STALL_STATUS

    def __init__(self, failure: HilError, stalls: list[Stall]):
        self.stalls = tuple(sorted(stalls, key=lambda stall: stall.at))
        told = "; ".join(stalls_in_words(self.stalls))
        where = ({"drives": failure.drives, "bus": failure.bus, "node": failure.node}
                 if isinstance(failure, BringUpError) else {})
        super().__init__([dataclasses.replace(d, hint=None) for d in failure.diagnostics] + [
            error(f"the bench itself stalled during the bring-up: {told}: the bench broke real "
                  "time, the drive need not have failed",
                  hint="a host that pauses the bench's processes (a shared VM) or a slow link "
                       "between them does this: run again, on quieter CPUs (--cpus), over a "
                       "quicker link, or in lock-step (--lock-step)")], **where)


def judged_bring_up(start: Callable[[], Feedback], publish: Callable[[Stall], None],
                    heard: Callable[[], list[Stall]],
                    stopping: Callable[[], bool]) -> Feedback:
    """``start()``'s feedback, the controller's own stalls watched meanwhile (each given to
    ``publish``, to be heard back with the others'). If it fails with a HilError (not
    because ``stopping()``), the stalls ``heard()`` from every process, waited for up to
    GRACE after the failure (a process reports its stall once it has ended), that overlap
    the bring-up and last BRING_UP_STALL or more make it :class:`BringUpStalled`; without
    such a stall the failure is raised as it was."""
    began = time.time()
    with StallWatch("control", publish, BRING_UP_STALL):
        try:
            return start()
        except HilError as failure:
            if stopping():
                raise
            failed_with = failure
    failed = time.time()
    stalls: list[Stall] = []
    while True:
        stalls += [stall for stall in heard() if stall.length >= BRING_UP_STALL
                   and stall.end >= began and stall.at <= failed]
        if stalls or time.time() >= failed + GRACE:
            break
        time.sleep(_POLL)
    if not stalls:
        raise failed_with
    raise BringUpStalled(failed_with, stalls) from None
