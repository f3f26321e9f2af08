"""Real-time loops on a stock kernel: pacing, scheduling, and what they achieved.

:class:`CyclePacer` releases a loop on absolute deadlines; :class:`PeriodStatistics`
records each cycle's period and busy time for reports and benchmarks.
"""

from __future__ import annotations

import contextlib
import ctypes
import gc
import math
import os
import sys
import threading
import time
from collections.abc import Callable

import numpy as np

#: SCHED_FIFO priority a real-time loop asks for (ros2_control's controller manager asks for
#: the same); 0 keeps the normal scheduler
REAL_TIME_PRIORITY = 50
#: SCHED_FIFO priority of a real-time process' other threads (its Zenoh and frame-handling
#: threads, all of a simulator's), just below its loop's (:func:`enter_real_time`)
IO_PRIORITY = REAL_TIME_PRIORITY - 1
#: SCHED_FIFO priority of a real-time process' side work (goals decoded, recordings encoded):
#: below its frame handling, which must preempt it (threads of one SCHED_FIFO priority do
#: not share a CPU: a first recording encoded on the controller's CPU held its frames
#: 10-14 ms, measured), above every normal process (its GIL must not wait behind them)
SIDE_PRIORITY = 40
#: prctl(2) option: the calling thread's timer slack in ns
PR_SET_TIMERSLACK = 29
#: the interpreter's thread switch interval while a real-time loop runs (s; Python's default
#: is 5 ms): the longest a thread holding the GIL (decoding a large goal, say) keeps the loop
#: waiting for it once the loop wakes
REAL_TIME_SWITCH_INTERVAL = 200e-6


class Ring:
    """The latest ``keep`` values of a series, in a buffer allocated and written once at the
    start (a long run neither grows nor shows growth in its memory figures), with the count
    over the whole run."""

    def __init__(self, keep: int):
        # np.full writes every page now: the memory is taken here, not value by value
        self._values = np.full(keep, np.nan)
        self.count = 0

    @property
    def keep(self) -> int:
        return len(self._values)

    def add(self, value: float) -> None:
        self._values[self.count % len(self._values)] = value
        self.count += 1

    def clear(self) -> None:
        self.count = 0

    @property
    def values(self) -> np.ndarray:
        """The values kept, oldest first."""
        ring = self._values
        if self.count <= len(ring):
            return ring[:self.count].copy()
        oldest = self.count % len(ring)
        return np.concatenate((ring[oldest:], ring[:oldest]))

    def percentiles_us(self, name: str) -> dict:
        """p50, p99 and max of the values kept (s), in us, named ``<name>_p50_us`` etc."""
        values = self.values * 1e6
        if not len(values):
            return {}
        return {f"{name}_p50_us": float(np.percentile(values, 50)),
                f"{name}_p99_us": float(np.percentile(values, 99)),
                f"{name}_max_us": float(values.max())}


class PeriodStatistics:
    """Real-time mode, in seconds: each cycle's period (from its release, when its frames
    start out, to the next release) and busy time (release to the end of its work). Counts
    over the whole run; the latest ``keep`` cycles for percentiles (:class:`Ring`). A cycle
    is missed when its period is over 1.5 nominal ones."""

    KEEP = 100_000

    def __init__(self, nominal: float, keep: int = KEEP):
        self.nominal = nominal
        self._periods = Ring(keep)
        self._busy = Ring(keep)
        self.missed = 0
        self.scheduling = "not started"    # what the loop's thread runs under (CyclePacer)

    @property
    def count(self) -> int:
        return self._periods.count

    def add(self, period: float, busy: float) -> None:
        self._periods.add(period)
        self._busy.add(busy)
        self.missed += period > 1.5 * self.nominal

    def clear(self) -> None:
        """Forget the cycles so far (a measurement starts here)."""
        self._periods.clear()
        self._busy.clear()
        self.missed = 0

    @property
    def samples(self) -> np.ndarray:
        """The periods kept, oldest first."""
        return self._periods.values

    @property
    def busy(self) -> np.ndarray:
        """The busy times kept, oldest first."""
        return self._busy.values

    def figures(self) -> dict:
        """The cycles kept: period mean, |period - nominal| and busy percentiles (us), with
        the counts over the whole run and the scheduling. Needs at least one cycle."""
        periods = self.samples
        errors = np.abs(periods - self.nominal) * 1e6
        busy = self.busy * 1e6
        return {"cycles": self.count, "period_mean_ms": float(periods.mean() * 1e3),
                "error_p50_us": float(np.percentile(errors, 50)),
                "error_p99_us": float(np.percentile(errors, 99)),
                "error_max_us": float(errors.max()), "missed": self.missed,
                "busy_p50_us": float(np.percentile(busy, 50)),
                "busy_p99_us": float(np.percentile(busy, 99)), "busy_max_us": float(busy.max()),
                "scheduling": self.scheduling}

    def summary(self) -> str:
        if not self.count:
            return f"{self.scheduling}; no cycles"
        f = self.figures()
        kept = self._periods.keep
        latest = "" if self.count <= kept else f" (the latest {kept})"
        return (f"{self.scheduling}; {self.count} cycles, missed {self.missed}; period "
                f"mean{latest} {f['period_mean_ms']:.3f} ms, |error| p50 {f['error_p50_us']:.0f} "
                f"us, p99 {f['error_p99_us']:.0f} us, max {f['error_max_us']:.0f} us; busy p50 "
                f"{f['busy_p50_us']:.0f} us, p99 {f['busy_p99_us']:.0f} us")


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


_collection_pauses = 0
_collection_was_enabled = True
_collection_lock = threading.Lock()


@contextlib.contextmanager
def paused_collection():
    """Python's cyclic garbage collector off while the block runs (process-wide; nested and
    concurrent blocks are counted). For a burst of allocations outside the real-time loop
    (decoding a large goal): a collection the burst triggers runs in one stretch, whichever
    thread it lands in, and held a 500 Hz control loop 3-4 ms (measured)."""
    global _collection_pauses, _collection_was_enabled
    with _collection_lock:
        _collection_pauses += 1
        if _collection_pauses == 1:
            _collection_was_enabled = gc.isenabled()
            gc.disable()
    try:
        yield
    finally:
        with _collection_lock:
            _collection_pauses -= 1
            if _collection_pauses == 0 and _collection_was_enabled:
                gc.enable()


def release_gradually(items: list, chunk: int = 200) -> None:
    """Empty ``items`` a chunk at a time: freeing a large list of objects in one go is one
    uninterruptible stretch under the GIL (5 ms for a decoded 10,000-point goal, measured);
    between chunks other threads get their turn."""
    while items:
        del items[-chunk:]


def use_fifo(priority: int) -> tuple[bool, str]:
    """The calling thread (and the threads it starts from now on) under SCHED_FIFO
    ``priority`` where the OS allows it; (whether it did, what it runs under, in words)."""
    if priority <= 0:
        return False, "normal scheduling"
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, AttributeError) as exc:
        why = getattr(exc, "strerror", None) or str(exc)
        return False, (f"normal scheduling (SCHED_FIFO {priority} refused: {why}; it needs "
                       "root, CAP_SYS_NICE or an rtprio limit)")
    return True, f"SCHED_FIFO {priority}"


def enter_real_time(priority: int = IO_PRIORITY, cpus: set[int] | None = None) -> str:
    """A real-time process, from its start: the calling thread under SCHED_FIFO
    ``priority`` (on ``cpus`` if given), and with it every thread started afterwards
    (Zenoh's, python-can's, canopen's), and a short thread switch interval. Call it before
    opening Zenoh sessions or buses. Under the normal scheduler a process' frame handling
    waited behind any other runnable thread of the machine (the visualiser's, a
    neighbour's); sim and controller each on a CPU of their own answered a cycle's frames
    in 1.1-1.5 ms at p99 where they shared two CPUs in 2.0 ms (measured). Returns the
    scheduling, in words."""
    sys.setswitchinterval(min(sys.getswitchinterval(), REAL_TIME_SWITCH_INTERVAL))
    words = use_fifo(priority)[1]
    if cpus:
        try:
            os.sched_setaffinity(0, cpus)
        except (OSError, AttributeError) as exc:
            return f"{words}, any CPU (CPUs {sorted(cpus)} refused: {exc})"
        return f"{words} on CPU {','.join(map(str, sorted(cpus)))}"
    return words


def real_time_cpus(cpus: set[int] | None = None) -> tuple[set[int] | None, set[int] | None,
                                                           set[int] | None]:
    """Where ``hil up`` puts (sim, controller, visualiser): the controller on the last CPU
    this process may use, the simulator on the one before, the visualiser on the others
    (anywhere, at SCHED_IDLE, where there are only two). None: anywhere (a single CPU)."""
    usable = sorted(cpus if cpus is not None else os.sched_getaffinity(0))
    if len(usable) < 2:
        return None, None, None
    rest = set(usable[:-2]) or None
    return {usable[-2]}, {usable[-1]}, rest


_side = threading.local()


def enter_side_work() -> None:
    """The calling thread, if it runs under SCHED_FIFO above SIDE_PRIORITY, down to
    SIDE_PRIORITY (once per thread: later calls cost nothing). For the threads a real-time
    process starts for other work than its loop and its frames."""
    if getattr(_side, "entered", False):
        return
    _side.entered = True
    try:
        if (os.sched_getscheduler(0) == os.SCHED_FIFO
                and os.sched_getparam(0).sched_priority > SIDE_PRIORITY):
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(SIDE_PRIORITY))
    except (OSError, AttributeError):
        pass


def enter_background() -> str:
    """A process that must never take time from the real-time ones (the visualiser, a
    supervisor): the calling thread, and every thread it starts afterwards, under
    SCHED_IDLE (it runs when nothing else wants the CPU); returns that, in words."""
    try:
        os.sched_setscheduler(0, os.SCHED_IDLE, os.sched_param(0))
    except (OSError, AttributeError) as exc:
        return f"normal scheduling (SCHED_IDLE refused: {exc})"
    return "SCHED_IDLE"


def _tighten_timer_slack() -> None:
    """PR_SET_TIMERSLACK to 1 ns for the calling thread (Linux; elsewhere nothing)."""
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        libc.prctl(PR_SET_TIMERSLACK, ctypes.c_ulong(1), 0, 0, 0)
    except (OSError, AttributeError):
        pass
