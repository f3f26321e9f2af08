"""Whether the host gave a real-time test the margins it judges (a pytest plugin of
conftest.py).

A real-time test judges wall-clock margins: a drive silent for five 100 Hz cycles is a
fault, an SDO answer later than canopen's timeout is a dead node. Some shared hosts
deschedule a whole vCPU for hundreds of milliseconds at a time and do not report it as
steal (seen on CI: 0.2-0.4 s gaps in a bare Python loop, about two thirds of its wall
time). On such a host the product is right to fault and the test cannot tell a defect
from the host's pause.

So a watcher process measures how late it wakes from 2 ms sleeps for the whole run. A
test marked ``real_time`` (the real-time fixtures mark the tests that use them) that fails
while the watcher saw a stall longer than the test's margin is reported as skipped,
*inconclusive*, with the stall and the failure in its reason, and the run ends with a
banner that counts them. A failure with no such stall stays a failure, and every other
test is judged as usual: on a host that does not stall, nothing changes.
"""

from __future__ import annotations

import collections
import subprocess
import sys
import threading
import time

import pytest

#: the margin a real-time test judges unless its marker says otherwise (s): five cycles
#: at 100 Hz, the controller's silence limit, the smallest wall-clock margin of the suite
DEFAULT_MARGIN = 0.05

#: the watcher: says "ready" once its loop begins, then prints "<wall clock> <length>" for
#: each late wake-up over 20 ms; ends when the run that started it is gone (its parent
#: changes), so it never outlives pytest
_WATCHER = """
import os, sys, time
parent = os.getppid()
last = time.time()
checked = last
print("ready", flush=True)
while True:
    time.sleep(0.002)
    now = time.time()
    if now - last > 0.02:
        print(f"{last:.6f} {now - last:.6f}", flush=True)
    if now - checked > 1.0:
        if os.getppid() != parent:
            sys.exit(0)
        checked = now
    last = now
"""

_started = pytest.StashKey[float]()


class HostStallWatch:
    """The host's stalls, as a watcher process saw them: (began, length) in s, the last
    100,000 of them."""

    def __init__(self) -> None:
        self._process = subprocess.Popen([sys.executable, "-c", _WATCHER],
                                         stdout=subprocess.PIPE, text=True)
        # A stall while the watcher's Python still starts is one it never measures (CI: a
        # test stopped it then, and its 0.3 s went unseen); the run's tests begin once it
        # watches.
        if self._process.stdout.readline() != "ready\n":
            raise RuntimeError(f"the host-stall watcher did not start "
                               f"(exit status {self._process.wait()})")
        self._stalls: collections.deque[tuple[float, float]] = collections.deque(maxlen=100_000)
        self._lock = threading.Lock()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for line in self._process.stdout:
            began, length = map(float, line.split())
            with self._lock:
                self._stalls.append((began, length))

    def longest_between(self, start: float, stop: float) -> tuple[float, int]:
        """The longest stall that overlaps [start, stop] (0 if none) and how many did."""
        with self._lock:
            seen = [length for began, length in self._stalls
                    if began < stop and began + length > start]
        return max(seen, default=0.0), len(seen)

    def longest(self) -> tuple[float, int]:
        """The longest stall of the whole run and how many there were."""
        with self._lock:
            return max((length for _, length in self._stalls), default=0.0), len(self._stalls)

    def close(self) -> None:
        self._process.terminate()
        self._process.wait(5)
        self._process.stdout.close()


class RealTimeJudge:
    """The plugin: times each test, turns a real-time test's failure during a host stall
    over its margin into an inconclusive skip, and says so at the end of the run."""

    def __init__(self) -> None:
        self.watch = HostStallWatch()
        self.inconclusive: list[str] = []

    @pytest.hookimpl(tryfirst=True)
    def pytest_runtest_setup(self, item: pytest.Item) -> None:
        item.stash[_started] = time.time()

    @pytest.hookimpl(hookwrapper=True)
    def pytest_runtest_makereport(self, item: pytest.Item, call: pytest.CallInfo):
        outcome = yield
        report = outcome.get_result()
        marker = item.get_closest_marker("real_time")
        if marker is None or not report.failed or call.excinfo is None:
            return
        margin = marker.kwargs.get("margin", DEFAULT_MARGIN)
        longest, count = self.watch.longest_between(item.stash.get(_started, call.start),
                                                    time.time())
        if longest <= margin:
            return
        failure = call.excinfo.exconly().strip().splitlines()[0][:300]
        reason = (f"inconclusive on this host: it stalled {longest * 1e3:.0f} ms (the longest "
                  f"of {count} stall(s) while the test ran) and the test judges real-time "
                  f"margins of {margin * 1e3:.0f} ms; the failure: {failure}")
        path, line, _ = item.reportinfo()
        report.outcome = "skipped"
        report.longrepr = (str(path), (line or 0) + 1, f"Skipped: {reason}")

    def pytest_runtest_logreport(self, report: pytest.TestReport) -> None:
        # counted where reports arrive: in this process, or from pytest-xdist's workers
        if report.skipped and isinstance(report.longrepr, tuple) \
                and "inconclusive on this host" in report.longrepr[2]:
            self.inconclusive.append(report.nodeid)

    def pytest_terminal_summary(self, terminalreporter) -> None:
        longest, count = self.watch.longest()
        if not self.inconclusive:
            if count:
                terminalreporter.write_line(
                    f"host stalls seen during the run: {count}, the longest {longest * 1e3:.0f} ms")
            return
        bar = "#" * 80
        terminalreporter.write_line(bar, yellow=True)
        terminalreporter.write_line(
            f"# {len(self.inconclusive)} REAL-TIME TESTS INCONCLUSIVE: they failed while this "
            f"host stalled longer than their margins", yellow=True)
        terminalreporter.write_line(
            f"# (this process saw {count} host stalls over 20 ms, the longest "
            f"{longest * 1e3:.0f} ms). Their failures are reported as skips; run them on a host "
            "that does not stall:", yellow=True)
        for nodeid in self.inconclusive:
            terminalreporter.write_line(f"#   {nodeid}", yellow=True)
        terminalreporter.write_line(bar, yellow=True)

    def pytest_unconfigure(self) -> None:
        self.watch.close()


def pytest_configure(config: pytest.Config) -> None:
    config.pluginmanager.register(RealTimeJudge(), "hil-real-time-judge")
