"""tools/uml_run.py: User-Mode Linux boots with its ptrace wrapper on every host.

On CPUs with AMX, Debian 12's UML hands ptrace an FPU-state buffer smaller than the
host's XSAVE area and panics at boot; tools/uml_xstate_ptrace.c bounces such requests
through a full-size buffer. These tests run the wrapper's undersized path on any host
with XSAVE (by handing it a buffer smaller than this host's area, as UML does on an AMX
host), and check that UML boots with the wrapper preloaded, on one host CPU.
"""

from __future__ import annotations

import ctypes
import errno
import os
import subprocess
import sys
import threading
import time

import pytest

from conftest import ROOT
from process_leaks import running_descendants

sys.path.insert(0, str(ROOT / "tools"))
import uml_run  # noqa: E402

PTRACE_GETREGSET = 0x4204
PTRACE_SETREGSET = 0x4205
NT_X86_XSTATE = 0x202
#: the legacy FXSAVE area and the XSAVE header: the smallest buffer UML could hand over
UNDERSIZED = 512 + 64
XMM0 = slice(160, 176)

_TRACEME = ("import ctypes, os, signal; ctypes.CDLL(None).ptrace(0, 0, None, None); "
            "os.kill(os.getpid(), signal.SIGSTOP)")


class _Iovec(ctypes.Structure):
    _fields_ = [("base", ctypes.c_void_p), ("len", ctypes.c_size_t)]


def _ptrace_function(library: ctypes.CDLL):
    function = library.ptrace
    function.restype = ctypes.c_long
    function.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p]
    return function


def _regset(ptrace, request: int, pid: int, buffer: ctypes.Array) -> tuple[int, int, int]:
    """(result, errno, bytes the kernel reported) of one NT_X86_XSTATE request."""
    iov = _Iovec(ctypes.addressof(buffer), len(buffer))
    ctypes.set_errno(0)
    result = ptrace(request, pid, NT_X86_XSTATE, ctypes.byref(iov))
    return result, ctypes.get_errno(), iov.len


@pytest.fixture
def wrapper():
    try:
        return uml_run.xstate_wrapper()
    except uml_run.UmlUnavailable as missing:
        pytest.skip(f"the ptrace wrapper cannot be built here: {missing}")


@pytest.fixture
def stopped_tracee():
    """A child process traced by this thread and stopped, as UML's processes are."""
    child = subprocess.Popen([sys.executable, "-c", _TRACEME])
    try:
        _, status = os.waitpid(child.pid, os.WUNTRACED)
        assert os.WIFSTOPPED(status), f"the tracee did not stop (wait status {status:#x})"
        yield child.pid
    finally:
        child.kill()
        child.wait()


def test_wrapper_completes_an_xstate_set_smaller_than_the_hosts_area(wrapper, stopped_tracee):
    libc = _ptrace_function(ctypes.CDLL(None, use_errno=True))
    wrapped = _ptrace_function(ctypes.CDLL(str(wrapper), use_errno=True))
    full = ctypes.create_string_buffer(64 * 1024)
    result, error, host_size = _regset(libc, PTRACE_GETREGSET, stopped_tracee, full)
    if result < 0 and error in (errno.EIO, errno.ENODEV, errno.EINVAL):
        pytest.skip(f"this CPU or kernel has no XSAVE state for ptrace ({os.strerror(error)})")
    assert result == 0, os.strerror(error)
    if host_size <= UNDERSIZED:
        pytest.skip(f"this host's XSAVE area is {host_size} bytes: no larger than the "
                    f"{UNDERSIZED}-byte buffer the test hands over")
    before = full.raw[:host_size]

    # what the kernel does with UML's undersized buffer on an AMX host
    part = ctypes.create_string_buffer(before[:UNDERSIZED], UNDERSIZED)
    result, error, _ = _regset(libc, PTRACE_SETREGSET, stopped_tracee, part)
    assert (result, error) == (-1, errno.EFAULT), \
        "the host kernel accepted a partial XSAVE area: the wrapper's premise changed"

    # through the wrapper: GET hands out the first part of the full state ...
    got = ctypes.create_string_buffer(UNDERSIZED)
    result, error, _ = _regset(wrapped, PTRACE_GETREGSET, stopped_tracee, got)
    assert result == 0, os.strerror(error)
    assert got.raw == before[:UNDERSIZED]

    # ... and SET writes the part, keeping the task's state past it
    changed = bytearray(got.raw)
    changed[XMM0] = bytes(range(0xA0, 0xB0))
    part = ctypes.create_string_buffer(bytes(changed), UNDERSIZED)
    result, error, _ = _regset(wrapped, PTRACE_SETREGSET, stopped_tracee, part)
    assert result == 0, f"SETREGSET through the wrapper failed: {os.strerror(error)}"
    result, error, _ = _regset(libc, PTRACE_GETREGSET, stopped_tracee, full)
    assert result == 0, os.strerror(error)
    after = full.raw[:host_size]
    assert after[XMM0] == bytes(range(0xA0, 0xB0))
    assert after[UNDERSIZED:] == before[UNDERSIZED:]


def test_wrapper_passes_a_full_size_xstate_request_through(wrapper, stopped_tracee):
    libc = _ptrace_function(ctypes.CDLL(None, use_errno=True))
    wrapped = _ptrace_function(ctypes.CDLL(str(wrapper), use_errno=True))
    full = ctypes.create_string_buffer(64 * 1024)
    result, error, host_size = _regset(libc, PTRACE_GETREGSET, stopped_tracee, full)
    if result < 0:
        pytest.skip(f"this CPU or kernel has no XSAVE state for ptrace ({os.strerror(error)})")
    exact = ctypes.create_string_buffer(host_size)
    result, error, size = _regset(wrapped, PTRACE_GETREGSET, stopped_tracee, exact)
    assert (result, size) == (0, host_size), os.strerror(error)
    assert exact.raw == full.raw[:host_size]
    result, error, _ = _regset(wrapped, PTRACE_SETREGSET, stopped_tracee, exact)
    assert result == 0, os.strerror(error)


def test_user_mode_linux_boots_with_the_wrapper_in_its_ptrace_path():
    missing, xstate = uml_run.trial_boot()
    if missing:
        pytest.skip(f"User-Mode Linux cannot run here: {missing}")
    # the wrapper logged UML's own FPU-state requests: it sat in the path of every one
    assert "SETREGSET uml_size=" in xstate and "GETREGSET uml_size=" in xstate, xstate


def test_commands_inside_user_mode_linux_run_with_avx512_off(tmp_path):
    if uml_run.available():
        pytest.skip(f"User-Mode Linux cannot run here: {uml_run.available()}")
    probe = tmp_path / "environment"       # UML's root is this machine's filesystem
    status = uml_run.run(["sh", "-c", f"env > {probe}"], ["vcan0"], timeout=120, memory="256M")
    assert status == 0
    inside = dict(line.split("=", 1) for line in probe.read_text().splitlines() if "=" in line)
    assert "-AVX512F" in inside["GLIBC_TUNABLES"]
    assert inside["OPENBLAS_CORETYPE"] == "Haswell"
    assert "LD_PRELOAD" not in inside


def test_user_mode_linux_and_its_processes_run_on_one_host_cpu(tmp_path):
    if uml_run.available():
        pytest.skip(f"User-Mode Linux cannot run here: {uml_run.available()}")
    started = tmp_path / "started"
    # this test's own helpers (the real-time judge's watcher) are not UML's
    before = running_descendants(os.getpid())
    inside = threading.Thread(target=uml_run.run, args=(
        ["sh", "-c", f"touch {started}; sleep 3"], ["vcan0"], 120, "256M"))
    inside.start()
    try:
        deadline = time.monotonic() + 60
        while not started.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        assert started.exists(), "the command inside UML did not start"
        allowed = {}
        for pid in running_descendants(os.getpid()) - before:
            try:
                allowed[pid] = os.sched_getaffinity(pid)
            except ProcessLookupError:
                continue
    finally:
        inside.join()
    assert len(allowed) >= 2, "found no UML processes (kernel and the command's host process)"
    assert set(map(frozenset, allowed.values())) == {frozenset({uml_run.uml_cpu()})}, allowed
