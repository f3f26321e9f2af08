"""The ``socketcan`` tests, run for real inside User-Mode Linux.

This machine's kernel has no CAN; tools/uml_run.py boots a UML kernel that has
vcan and runs ``pytest -m socketcan`` there. Where UML is not installed this
test is skipped with the reason (CI installs it: see .ci/run).
"""

from __future__ import annotations

import re
import subprocess
import sys
import warnings

import pytest

from conftest import ROOT, socketcan_missing

sys.path.insert(0, str(ROOT / "tools"))
import uml_run  # noqa: E402


@pytest.mark.slow      # boots a kernel and runs the socketcan tests there: minutes
@pytest.mark.timeout(1900)            # beyond the run's own limit below (1860 s)
def test_socketcan_suite_passes_inside_user_mode_linux(request):
    if socketcan_missing() is None:
        pytest.skip("this kernel has vcan0: the socketcan tests ran directly")
    missing = uml_run.available()
    if missing:
        pytest.skip(f"User-Mode Linux unavailable: {missing}")
    result = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "uml_run.py"), "--timeout", "1800",
         "--vcan", "vcan0", "--vcan", "vcan1",
         # can0: the name client libraries that open SocketCAN hard-wire (TMotorCANControl,
         # motor-python), a vxcan pair whose other end hil-can0 the simulated drives take
         "--vcan", "can0:hil-can0",
         # vcancc0: a classical-only vcan (MTU 16; a vcan takes CAN FD frames), where the
         # kernel refuses an FD frame (test_toy_protocol.py)
         "--vcan", "vcancc0+classic", "--",
         sys.executable, "-m", "pytest", "-m", "socketcan", "-p", "no:cacheprovider",
         "-q", "-rfEs", "--tb=short", "--color=no",
         # a lock-step demo inside UML on CI's shared vCPUs: over 300 s
         "--timeout=600", *_files_with_socketcan_tests(request.session)],
        cwd=ROOT, capture_output=True, text=True, timeout=1860)
    output = result.stdout + result.stderr
    # which tests failed first (a CI log keeps only the message's tail), then the details
    start = output.rfind("short test summary info")
    summary = output[start:start + 3000] if start >= 0 else ""
    assert result.returncode == 0, f"{summary}\n...\n{output[-5000:]}"
    assert " passed" in output, output[-3000:]
    # no socketcan test may be skipped in there, but for a real-time test that failed while
    # the host stalled past its margins (tests/host_stalls.py): told here as a warning
    skips = re.findall(r"^SKIPPED \[\d+\] (.*)$", output, re.MULTILINE)
    unexplained = [s for s in skips if "inconclusive on this host" not in s]
    assert not unexplained, "\n".join(unexplained)
    for skip in skips:
        warnings.warn(f"inside User-Mode Linux: {skip}", stacklevel=1)


def _files_with_socketcan_tests(session: pytest.Session) -> list[str]:
    """The test files of this run's ``socketcan`` tests, for the run inside UML to collect
    (importing every test file there took minutes); all of tests/ when this run has none
    (this file run alone)."""
    files = {str(item.path) for item in session.items
             if item.get_closest_marker("socketcan") is not None}
    return sorted(files) or [str(ROOT / "tests")]
