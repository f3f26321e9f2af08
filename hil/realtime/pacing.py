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
    and records each cycle (and its spin now) in ``statistics``. Create it in the loop's
    thread, call :meth:`release` at the top of each cycle and :meth:`close` when the loop
    ends.

    What real-time loops on a stock Linux kernel do, each measured here:

    * the thread runs under SCHED_FIFO ``priority`` where the OS allows it (root,
      CAP_SYS_NICE or an rtprio limit), as ros2_control's controller manager asks for: under
      the normal scheduler, any other runnable thread may delay a wake-up by milliseconds;
      :attr:`PeriodStatistics.scheduling` says what it got;
    * it sleeps until a spin before the deadline and busy-waits the rest: a sleeping thread
      wakes tens of microseconds late, and that lateness would be the period error. The spin
      is the SPIN_QUANTILE of the thread's own wake-up lateness over its last SPIN_WINDOW
      sleeps (SPIN until it has them; at least MIN_SPIN, at most SPIN or half a period):
      the spin is CPU burnt every cycle, and what this host needs is measured, not
      guessed (a fixed spin burnt more than this host's wake-ups needed:
      docs/performance.md, "2026-11-26, evening: issue 28's bounds on this commit");
    * the timer slack is 1 ns (under the normal scheduler the kernel may otherwise wake a
      sleeper 50 us late to batch wake-ups);
    * the interpreter switches threads every REAL_TIME_SWITCH_INTERVAL instead of 5 ms:
      another thread in pure Python (a 10,000-point goal being decoded) held the loop a
      whole switch interval at each wake-up, and a 500 Hz controller missed cycles
      (docs/performance.md, "2026-12-06, later: figures from code comments").
    """

    #: a loop this many periods behind starts afresh instead of running its cycles back to back
    RESYNC = 10
    #: the last part of each wait, busy (s), until the wake-ups are measured; the most it
    #: ever is (and at most half a period)
    SPIN = 100e-6
    #: the least spin (s)
    MIN_SPIN = 10e-6
    #: the spin covers this share of the measured wake-ups ...
    SPIN_QUANTILE = 0.99
    #: ... of the last this many sleeps (re-measured every as many)
    SPIN_WINDOW = 512

    def __init__(self, period: float, statistics: PeriodStatistics,
                 priority: int = REAL_TIME_PRIORITY,
                 clock: Callable[[], float] = time.perf_counter,
                 sleep: Callable[[float], None] = time.sleep):
        self.period = period
        self.statistics = statistics
        self._clock, self._sleep = clock, sleep
        self._most_spin = min(self.SPIN, period / 2)
        self.spin = statistics.spin = self._most_spin
        self._lateness: list[float] = []       # the last SPIN_WINDOW sleeps' wake-ups (s)
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
            if delay > self.spin:
                self._sleep(delay - self.spin)
                self._woke(self._clock() - (self._deadline - self.spin))
            elif delay < -self.RESYNC * self.period:
                self._deadline = now
        released = self._clock()
        while released < self._deadline:
            released = self._clock()
        if self._released is not None:
            self.last_period = released - self._released
            self.statistics.add(self.last_period, now - self._released)
        self._released = released

    def _woke(self, late: float) -> None:
        """A sleep ended ``late`` after it was due: every SPIN_WINDOW of them, the spin
        becomes their SPIN_QUANTILE (within MIN_SPIN and the most)."""
        lateness = self._lateness
        lateness.append(late)
        if len(lateness) == self.SPIN_WINDOW:
            lateness.sort()
            covered = lateness[min(len(lateness) - 1, int(self.SPIN_QUANTILE * len(lateness)))]
            self.spin = self.statistics.spin = min(max(covered, self.MIN_SPIN), self._most_spin)
            lateness.clear()


def _tighten_timer_slack() -> None:
    """PR_SET_TIMERSLACK to 1 ns for the calling thread (Linux; elsewhere nothing)."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_TIMERSLACK, ctypes.c_ulong(1), 0, 0, 0)
    except (OSError, AttributeError):
        pass
