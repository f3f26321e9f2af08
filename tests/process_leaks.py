"""No process a test starts outlives it (a pytest plugin, loaded by conftest).

A test that starts `hil` processes and fails before its fixture yields (a controller that
did not come up, say) used to leave the others running: a real-time sim spinning at half a
CPU for the rest of the run, slowing every later test on a 2-vCPU host until the run ran
out of time (CI, 2026-11-29). After each test this plugin looks for descendants of the
pytest process that the test started and that are still running, ends them (SIGTERM, then
SIGKILL), and fails the teardown of a test that passed: a leak is the test's defect. After
a test that failed (or was skipped), the leftovers are only ended: the failure is the news.
A process still ending (signalled by the test, not waited for) gets SETTLE_S to end by
itself first: on a loaded host a stack's shutdown takes seconds, and that is no leak.

Descendants whose parent died are re-parented out of our tree and are not seen.
"""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import pytest

#: how long the leftovers get to end on SIGTERM before SIGKILL
_GRACE_S = 5.0
#: how long what a test left gets to end by itself before it counts as left running (s)
SETTLE_S = 10.0


def state_and_parent(pid: int) -> tuple[str, int] | None:
    """A process' state letter (R, S, Z...) and its parent's pid, from /proc; None once it
    is gone."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    # "pid (comm) state ppid ...": comm may hold spaces and parentheses
    state, ppid = stat[stat.rfind(")") + 2:].split()[:2]
    return state, int(ppid)


def _running_children() -> dict[int, list[int]]:
    """Parent pid -> pids of its running (not zombie) children, from /proc."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        known = state_and_parent(int(entry.name))
        if known is not None and known[0] != "Z":
            children.setdefault(known[1], []).append(int(entry.name))
    return children


def running_descendants(pid: int) -> set[int]:
    """The running descendants of ``pid``."""
    children = _running_children()
    found: set[int] = set()
    todo = list(children.get(pid, ()))
    while todo:
        child = todo.pop()
        if child not in found:
            found.add(child)
            todo.extend(children.get(child, ()))
    return found


def _command_line(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()[:160]
    except OSError:
        return "(ended)"


def _still_running(pids: set[int], wait: float) -> set[int]:
    """Those of ``pids`` still running after up to ``wait`` s."""
    deadline = time.monotonic() + wait
    while pids and time.monotonic() < deadline:
        time.sleep(0.05)
        pids = pids & running_descendants(os.getpid())
    return pids


def _end(pids: set[int]) -> None:
    for sig, wait in ((signal.SIGTERM, _GRACE_S), (signal.SIGKILL, 1.0)):
        for pid in pids:
            try:
                os.kill(pid, sig)
            except ProcessLookupError:
                pass
        pids = _still_running(pids, wait)


class ProcessLeaks:
    """The plugin: an autouse fixture and the call phase's outcome it needs."""

    @pytest.hookimpl(wrapper=True)
    def pytest_runtest_makereport(self, item: pytest.Item, call: pytest.CallInfo):
        report = yield
        if report.when == "call":
            item.stash[_CALL_PASSED] = report.passed
        return report

    @pytest.fixture(autouse=True)
    def no_process_outlives_its_test(self, request: pytest.FixtureRequest):
        # autouse and function scoped: set up after the wider fixtures (whose processes
        # are in `before`), torn down after the test's other fixtures
        before = running_descendants(os.getpid())
        yield
        left = running_descendants(os.getpid()) - before
        if left:
            left = _still_running(left, SETTLE_S)
        if not left:
            return
        lines = [f"  {pid}: {_command_line(pid)}" for pid in sorted(left)]
        _end(left)
        if request.node.stash.get(_CALL_PASSED, False):
            pytest.fail(f"{len(left)} process(es) the test started were still running after "
                        "it (ended now):\n" + "\n".join(lines), pytrace=False)


_CALL_PASSED = pytest.StashKey[bool]()


def pytest_configure(config: pytest.Config) -> None:
    config.pluginmanager.register(ProcessLeaks(), "hil-process-leaks")
