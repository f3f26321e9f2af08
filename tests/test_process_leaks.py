"""tests/process_leaks.py: a process a test leaves running is ended after the test, and a
test that passed fails its teardown for it."""

from __future__ import annotations

import textwrap

from conftest import TESTS
from process_leaks import state_and_parent

pytest_plugins = ["pytester"]

INNER = textwrap.dedent("""\
    import subprocess
    import sys
    import pytest

    # ends half a second after SIGTERM, as a stack's process shuts down
    SLOW_TO_END = ("import signal, sys, time; signal.signal(signal.SIGTERM, lambda *a: "
                   "(time.sleep(0.5), sys.exit(0))); print('ready', flush=True); time.sleep(600)")

    def start_sleeper(tmp_path, name):
        process = subprocess.Popen(["sleep", "600"])
        (tmp_path.parent.parent / f"{name}.pid").write_text(str(process.pid))
        return process

    def test_passing_but_leaving_a_process(tmp_path):
        start_sleeper(tmp_path, "leaky")

    def test_failing_and_leaving_a_process(tmp_path):
        start_sleeper(tmp_path, "failing")
        assert False, "the test's own failure"

    def test_ending_its_process(tmp_path):
        process = start_sleeper(tmp_path, "tidy")
        process.kill()
        process.wait()

    def test_stopping_its_process_without_waiting_for_it():
        process = subprocess.Popen([sys.executable, "-c", SLOW_TO_END], stdout=subprocess.PIPE)
        assert process.stdout.readline().strip() == b"ready"
        process.terminate()
    """)


def _running(pid: int) -> bool:
    known = state_and_parent(pid)
    return known is not None and known[0] != "Z"


def test_a_left_process_is_ended_and_fails_a_passing_test_only(pytester):
    """A process still ending when its test ends is given its time and no failure."""
    pytester.makeconftest(f"import sys\nsys.path.insert(0, {str(TESTS)!r})\n"
                          "import process_leaks\nprocess_leaks.SETTLE_S = 5.0\n"
                          "pytest_plugins = ['process_leaks']\n")
    pytester.makepyfile(test_inner=INNER)
    result = pytester.runpytest_subprocess("-rfE", "-p", "no:cacheprovider",
                                           f"--basetemp={pytester.path / 'tmp'}")
    result.assert_outcomes(passed=3, failed=1, errors=1)
    output = result.stdout.str()
    assert "ERROR test_inner.py::test_passing_but_leaving_a_process" in output
    result.stdout.fnmatch_lines(["*1 process(es) the test started were still running after it*",
                                 "*sleep 600*"])
    assert "FAILED test_inner.py::test_failing_and_leaving_a_process" in output
    assert "ERROR test_inner.py::test_failing_and_leaving_a_process" not in output
    # both leftovers ended by the inner run, before it finished
    for name in ("leaky", "failing"):
        pid = int((pytester.path / f"{name}.pid").read_text())
        assert not _running(pid), name
