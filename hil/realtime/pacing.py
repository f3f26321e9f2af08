"""Releasing a real-time loop on absolute deadlines (:class:`CyclePacer`)."""

from __future__ import annotations

import ctypes
import math
import os
import sys
import time
from collections.abc import Callable

from hil.realtime.scheduling import REAL_TIME_PRIORITY, REAL_TIME_SWITCH_INTERVAL, use_fifo
from hil.realtime.statistics import PeriodStatistics

#: prctl(2) option: the calling thread's timer slack in ns
PR_SET_TIMERSLACK = 29


class CyclePacer:
    """Releases a real-time loop every ``period`` seconds, on absolute deadlines (no drift),
    and records each cycle in ``statistics``. Create it in the loop's thread, call
    :meth:`release` at the top of each cycle and :meth:`close` when the loop ends.

    What real-time loops on a stock Linux kernel do, each measured here:

    * the thread runs under SCHED_FIFO ``priority`` where the OS allows it (root,
      CAP_SYS_NICE or an rtprio limit), as ros2_control's controller manager asks for: under
      the normal scheduler, any other runnable thread may delay a wake-up by milliseconds;
      :attr:`PeriodStatistics.scheduling` says what it got;
    * it sleeps until SPIN before the deadline and busy-waits the rest: a sleeping thread
      wakes tens of microseconds late, and that lateness would be the period error. The spin
      costs up to SPIN of CPU per cycle (10 % of a core at 1 kHz);
    * the timer slack is 1 ns (under the normal scheduler the kernel may otherwise wake a
      sleeper 50 us late to batch wake-ups);
    * the interpreter switches threads every REAL_TIME_SWITCH_INTERVAL instead of 5 ms:
      another thread in pure Python (a 10,000-point goal being decoded) held the loop up to
      5 ms at each wake-up (a 500 Hz controller missed 21 cycles in one such goal, measured).
    """

    #: a loop this many periods behind starts afresh instead of running its cycles back to back
    RESYNC = 10
    #: the last part of each wait, busy (s); at most half a period
    SPIN = 100e-6

    def __init__(self, period: float, statistics: PeriodStatistics,
                 priority: int = REAL_TIME_PRIORITY,
                 clock: Callable[[], float] = time.perf_counter,
                 sleep: Callable[[float], None] = time.sleep):
        self.period = period
        self.statistics = statistics
        self._clock, self._sleep = clock, sleep
        self._spin = min(self.SPIN, period / 2)
        self._deadline: float | None = None
        self._released: float | None = None
        #: the period of the cycle before this one (s; NaN before the second release)
        self.last_period = math.nan
        self._fifo = False
        _tighten_timer_slack()
        self._switch_interval = sys.getswitchinterval()
        sys.setswitchinterval(min(self._switch_interval, REAL_TIME_SWITCH_INTERVAL))
        statistics.scheduling = self._schedule(priority)

    def _schedule(self, priority: int) -> str:
        self._fifo, words = use_fifo(priority)
        return words

    def close(self) -> None:
        """Back to the normal scheduler (the thread goes on to non-real-time work)."""
        sys.setswitchinterval(self._switch_interval)
        if self._fifo:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
            self._fifo = False

    def release(self) -> None:
        """Wait for this cycle's deadline (the first call returns at once)."""
        now = self._clock()
        if self._deadline is None:
            self._deadline = now
        else:
            self._deadline += self.period
            delay = self._deadline - now
            if delay > self._spin:
                self._sleep(delay - self._spin)
            elif delay < -self.RESYNC * self.period:
                self._deadline = now
        released = self._clock()
        while released < self._deadline:
            released = self._clock()
        if self._released is not None:
            self.last_period = released - self._released
            self.statistics.add(self.last_period, now - self._released)
        self._released = released


def _tighten_timer_slack() -> None:
    """PR_SET_TIMERSLACK to 1 ns for the calling thread (Linux; elsewhere nothing)."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_TIMERSLACK, ctypes.c_ulong(1), 0, 0, 0)
    except (OSError, AttributeError):
        pass
