"""A real-time process' own stalls: when it did not run for longer than it should have,
by how much, and how much of the machine's time the hypervisor took meanwhile.

A bench that reports its own stall as a device's fault sends engineers after a bug that is
not there (Simulink Real-Time, VeriStand and OPAL-RT count their overruns for that reason).
Each real-time process of hil finds its stalls from its own wake-ups (:class:`StallDetector`)
and reports them; the controller holds them against the drives it finds silent.
"""

from __future__ import annotations

import math
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from datetime import datetime

#: a wake-up this much later than due is a stall (s): far above a SCHED_FIFO thread's
#: wake-up jitter (tens of us), below a cycle's worth of a drive's silence limit
STALL_THRESHOLD = 0.005
#: a command's exit status where the bench's own stalls explain its failure: the bench broke
#: real time, the device did not fail (1: the device's failure, or the user's). hil up: every
#: fault explained by a stall, a bring-up failed during one, or --max-stalls passed; hil
#: control: its bring-up so failed; hil bench: a real-time run did not start
BENCH_STALL_STATUS = 3
#: what each process is called in words
PROCESS_WORDS = {"sim": "the simulator", "control": "the controller",
                 "transport": "the Zenoh transport", "link": "the link"}
#: how often a detector reads the machine's steal time (s): reading /proc/stat at every
#: wake-up cost a simulator inside User-Mode Linux enough to miss its answers
STEAL_REFRESH = 1.0


@dataclass(frozen=True)
class Stall:
    """A stretch in which ``process`` did not run: from ``at`` (wall clock, s since the
    epoch) for ``length`` s; ``steal`` s of CPU time the hypervisor took from the machine's
    CPUs in the ``steal_window`` s that hold the stall (NaN: not measured). Found from
    wake-ups ``resolution`` s apart, it may have begun up to that much earlier (and lasted
    that much longer). ``where``: what stalled within the process (the transport: the
    CAN channel whose message came late; the link: the CAN channel whose messages took
    ``length`` from their put to the echo of their answer)."""

    process: str
    at: float
    length: float
    steal: float = math.nan
    resolution: float = 0.0
    steal_window: float = math.nan
    where: str = ""

    @property
    def end(self) -> float:
        """When it ended (wall clock, s since the epoch)."""
        return self.at + self.length

    def __str__(self) -> str:
        # the window stays in the process that measured it (hil_msgs/Stall carries no window)
        window = ("" if math.isnan(self.steal_window)
                  else f" in the {self.steal_window * 1e3:.0f} ms")
        steal = ("" if math.isnan(self.steal) else
                 f" (hypervisor steal {self.steal * 1e3:.0f} ms{window} around it)")
        when = clock_time(self.at)
        what = PROCESS_WORDS.get(self.process, self.process)
        if self.process == "transport":
            return (f"{what} delivered a message of {self.where or 'a CAN channel'} "
                    f"{self.length * 1e3:.0f} ms late at {when}{steal}")
        if self.process == "link":
            return (f"{what} of {self.where or 'a CAN channel'} took {self.length * 1e3:.0f} ms "
                    f"a round trip at {when}")
        return f"{what} stalled {self.length * 1e3:.0f} ms at {when}{steal}"


def clock_time(at: float) -> str:
    """Wall time ``at`` (s since the epoch) as a stall is told in words: HH:MM:SS.mmm."""
    return datetime.fromtimestamp(at).strftime("%H:%M:%S.%f")[:-3]


def steal_seconds() -> float:
    """The machine's CPU time taken by the hypervisor since boot, all CPUs (s; NaN where the
    kernel does not say: /proc/stat's steal column)."""
    try:
        with open("/proc/stat") as stat:
            fields = stat.readline().split()
        return int(fields[8]) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return math.nan


class StallDetector:
    """Finds the stalls of a thread that means to wake every ``period`` s: :meth:`tick`,
    called at each wake-up, returns the :class:`Stall` when this one came over
    ``threshold`` late (or :meth:`late`, where the caller measures). Counts them over the
    run."""

    def __init__(self, process: str, period: float, threshold: float = STALL_THRESHOLD,
                 clock: Callable[[], float] = time.monotonic,
                 wall: Callable[[], float] = time.time,
                 steal: Callable[[], float] = steal_seconds):
        self.process, self.period, self.threshold = process, period, threshold
        self._clock, self._wall, self._steal = clock, wall, steal
        self._last: float | None = None                     # the last tick's clock
        self._steal_mark: tuple[float, float] | None = None  # (clock, steal) last read
        self.count = 0
        self.longest = 0.0

    def tick(self) -> Stall | None:
        """At a wake-up: the stall before it, if it came late, with the steal since the
        last reading (at most STEAL_REFRESH before the stall, or the previous stall)."""
        now = self._clock()
        last, self._last = self._last, now
        if self._steal_mark is None or now - self._steal_mark[0] >= STEAL_REFRESH:
            if last is None or now - last - self.period <= self.threshold:
                self._steal_mark = (now, self._steal())
        if last is None:
            return None
        lateness = now - last - self.period
        if not lateness > self.threshold:
            return None
        marked, before = self._steal_mark
        self._steal_mark = (now, self._steal())
        return self.late(lateness, steal=self._steal_mark[1] - before,
                         resolution=self.period, steal_window=now - marked)

    def late(self, lateness: float, woke: float | None = None, steal: float = math.nan,
             resolution: float = 0.0, steal_window: float = math.nan) -> Stall | None:
        """A wake-up ``lateness`` s late, at wall time ``woke`` (now if None), found by the
        caller where it measures its own periods (a paced loop): the stall, counted, if it is
        over the threshold."""
        if not lateness > self.threshold:        # NaN (no period yet) is no stall
            return None
        self.count += 1
        self.longest = max(self.longest, lateness)
        woke = self._wall() if woke is None else woke
        return Stall(self.process, woke - lateness, lateness, steal, resolution, steal_window)

    def summary(self) -> str:
        """The run's stalls in words."""
        if not self.count:
            return f"no stall over {self.threshold * 1e3:g} ms"
        return f"{self.count} stall(s) over {self.threshold * 1e3:g} ms, longest " \
               f"{self.longest * 1e3:.0f} ms"


class StallTally:
    """Stalls counted per process, with the longest of each: what a run reports."""

    def __init__(self):
        self._counts: dict[str, tuple[int, float]] = {}

    def add(self, stall: Stall) -> None:
        count, longest = self._counts.get(stall.process, (0, 0.0))
        self._counts[stall.process] = (count + 1, max(longest, stall.length))

    @property
    def total(self) -> int:
        """Stalls of every process."""
        return sum(count for count, _ in self._counts.values())

    def figures(self) -> dict[str, dict[str, float]]:
        """{process: {"count": n, "longest_ms": ms}}."""
        return {process: {"count": count, "longest_ms": round(longest * 1e3, 1)}
                for process, (count, longest) in sorted(self._counts.items())}

    def summary(self, threshold: float = STALL_THRESHOLD) -> str:
        """In words, per process: 'sim 2 (longest 19 ms), transport 5 (longest 7 ms)'."""
        if not self._counts:
            return f"no stall over {threshold * 1e3:g} ms"
        return f"stalls over {threshold * 1e3:g} ms: " + ", ".join(
            f"{process} {count} (longest {longest * 1e3:.0f} ms)"
            for process, (count, longest) in sorted(self._counts.items()))


class StallWatch:
    """A thread of its own, while open, that wakes every ``period`` s and hands each stall of
    ``process`` over ``threshold`` to ``report``: the stalls of a process where no paced loop
    of its own runs to find them (the controller's bring-up). A stall of the whole process
    (descheduled, a hypervisor's pause) is found; so is the interpreter lock held longer
    than that by another thread of it, which stalls its real-time work alike."""

    def __init__(self, process: str, report: Callable[[Stall], None], threshold: float,
                 period: float = 0.01):
        self._detector = StallDetector(process, period, threshold)
        self._report = report
        self._watching, self._closed = threading.Event(), threading.Event()
        self._thread = threading.Thread(target=self._watch, name=f"{process} stall watch",
                                        daemon=True)

    def __enter__(self) -> StallWatch:
        self._thread.start()
        self._watching.wait()            # a stall from here on is found
        return self

    def __exit__(self, *exc_info: object) -> None:
        self._closed.set()
        self._thread.join()

    def _watch(self) -> None:
        self._detector.tick()
        self._watching.set()
        while True:
            closed = self._closed.wait(self._detector.period)
            # the wake-up that closes it still measures: a stall up to the close is found
            stall = self._detector.tick()
            if stall is not None:
                self._report(stall)
            if closed:
                return
