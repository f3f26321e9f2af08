"""Supervising ``hil`` child processes: start each with its log, notice one that dies,
stop them in a known order (SIGTERM, then SIGKILL past a timeout).

Children run in their own session, so Ctrl-C reaches the supervisor only, and they stop
themselves if it is killed (:func:`end_with_parent_if_asked`, which every ``hil`` command
calls). ``hil up`` and ``hil bench`` both supervise their children with it.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

#: how long each child may take to come up (s); the first run compiles MuJoCo models
START_TIMEOUT = 60.0
#: how long each child may take to stop after SIGTERM before it is killed (s)
STOP_TIMEOUT = 15.0
#: ... but a visualiser writes what it still holds of the run before it goes: on a loaded
#: host that can take longer, so it is given this long (s)
RECORDER_STOP_TIMEOUT = 60.0
LAST_LINES = 15
#: set in every child: the pid whose death must end the child too
PARENT_PID_VARIABLE = "HIL_PARENT_PID"


@dataclass
class Child:
    """One ``hil`` sub-process, its log file and what it must be stopped with. ``name`` is
    its role (``sim``, ``control``, ``viz``: its liveliness token's name); ``robot`` names the
    robot it serves where a run has several."""

    name: str
    argv: list[str]
    log_path: Path
    robot: str = ""
    process: subprocess.Popen | None = None
    expected_exit: bool = False
    #: started with a pipe on its standard input, which :meth:`release` closes (``hil control
    #: --hold`` waits for that)
    held: bool = False
    #: how long it may take to stop after SIGTERM before it is killed (s)
    stop_timeout: float = STOP_TIMEOUT

    @property
    def label(self) -> str:
        """The child in words: its role, with its robot where a run has several."""
        return f"{self.robot} {self.name}" if self.robot else self.name

    def start(self) -> None:
        env = dict(os.environ, PYTHONUNBUFFERED="1", **{PARENT_PID_VARIABLE: str(os.getpid())})
        with open(self.log_path, "wb") as log:
            self.process = subprocess.Popen(
                [sys.executable, "-m", "hil", *self.argv], stdout=log, stderr=subprocess.STDOUT,
                stdin=subprocess.PIPE if self.held else subprocess.DEVNULL, env=env,
                start_new_session=True)

    def release(self) -> None:
        """End a held child's standard input: the word it waits for."""
        if self.process is not None and self.process.stdin is not None:
            self.process.stdin.close()

    @property
    def pid(self) -> int:
        return self.process.pid

    def exited(self) -> int | None:
        return None if self.process is None else self.process.poll()

    def last_lines(self) -> str:
        try:
            with open(self.log_path, errors="replace") as log:
                lines = deque(log, maxlen=LAST_LINES)
        except OSError:
            return "    (no log)"
        return "".join(f"    {line}" for line in lines).rstrip() or "    (its log is empty)"

    def stop(self) -> str | None:
        """SIGTERM, wait, SIGKILL if needed; return a problem in words, or None."""
        if self.process is None or self.process.poll() is not None:
            return None
        self.expected_exit = True
        self.process.send_signal(signal.SIGTERM)
        try:
            status = self.process.wait(self.stop_timeout)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
            return f"{self.label} did not stop within {self.stop_timeout:g} s and was killed"
        return None if status == 0 else f"{self.label} stopped with status {status}"


class ChildFailed(Exception):
    """A child exited (or failed to come up) while it should have been running; ``status``:
    its exit status (None: it did not come up in time)."""

    def __init__(self, message: str, status: int | None = None):
        super().__init__(message)
        self.status = status


class Run:
    """The children of one run (``hil up``, a bench run) and their supervision; ``stop``
    set (Ctrl-C, SIGTERM) ends every wait early."""

    def __init__(self, children: list[Child], stop: threading.Event | None = None):
        self.children = children
        self.stop = stop or threading.Event()

    def check(self) -> None:
        """Raise ChildFailed naming a child that has died unexpectedly."""
        for child in self.children:
            status = child.exited()
            if status is not None and not child.expected_exit:
                raise ChildFailed(f"{child.label} (pid {child.pid}) exited with status {status}; "
                                  f"its last lines ({child.log_path}):\n{child.last_lines()}",
                                  status)

    def wait(self, seconds: float) -> None:
        """Sleep up to ``seconds``, checking the children; return early when stopped."""
        deadline = time.monotonic() + seconds
        while not self.stop.is_set() and time.monotonic() < deadline:
            self.check()
            self.stop.wait(min(0.1, max(0.0, deadline - time.monotonic())))

    def wait_until(self, child: Child, ready: Callable[[float], bool], what: str) -> None:
        """Call ``ready(timeout)`` until it says yes, checking the children between calls;
        raise ChildFailed if one dies or ``child`` is not ``what`` within START_TIMEOUT."""
        deadline = time.monotonic() + START_TIMEOUT
        while not ready(0.1):
            self.check()
            if self.stop.is_set():
                return
            if time.monotonic() > deadline:
                raise ChildFailed(f"{child.label} (pid {child.pid}) was not {what} within "
                                  f"{START_TIMEOUT:g} s; its last lines ({child.log_path}):\n"
                                  f"{child.last_lines()}")

    def wait_for_line(self, child: Child, text: str) -> None:
        """Wait until ``child``'s log holds ``text`` (its banner), as :meth:`wait_until`."""
        def logged(timeout: float) -> bool:
            if text in child.log_path.read_text(errors="replace"):
                return True
            time.sleep(timeout)
            return False

        self.wait_until(child, logged, f"up (no {text!r} in its log)")

    def shut_down(self) -> list[str]:
        """Stop the running children: controllers (their drives disabled; in lock-step they
        close once the visualiser has logged their last frame), the visualiser (it records
        what is still on its way), then the sims; return problems. Stopped after the sims,
        whose session holds the meeting point, a visualiser twice did not stop at all."""
        order = {"control": 0, "viz": 1, "sim": 2}
        problems = []
        for child in sorted(self.children, key=lambda c: order[c.name]):
            child.expected_exit = True
            problem = child.stop()
            if problem:
                problems.append(problem)
        return problems


#: how long a viewer may take to go after SIGTERM before it is killed (s): it holds no state
VIEWER_STOP_TIMEOUT = 2.0


def run_foreground(command: list[str]) -> int:
    """Run a program (a viewer) until it ends or this process is told to stop (Ctrl-C,
    SIGTERM); then it and every process it started are stopped (SIGTERM to its session's
    group, SIGKILL past VIEWER_STOP_TIMEOUT): a viewer's launcher often hands over to a
    binary of its own, which killing the launcher alone would leave running. Its exit
    status; 0 when stopped so."""
    process = subprocess.Popen(command, start_new_session=True)
    # both signals handled here: a process started in the background of a shell inherits
    # SIGINT ignored, and Python then raises no KeyboardInterrupt for it
    previous = {s: signal.signal(s, _interrupted) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        return process.wait()
    except KeyboardInterrupt:
        return 0
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)
        _stop_group(process)


def _interrupted(signum, frame) -> None:
    raise KeyboardInterrupt


def _stop_group(process: subprocess.Popen) -> None:
    for stop, wait in ((signal.SIGTERM, VIEWER_STOP_TIMEOUT), (signal.SIGKILL, 5.0)):
        try:
            os.killpg(process.pid, stop)
        except ProcessLookupError:
            break                        # the group is gone: nothing was left running
        try:
            process.wait(wait)
        except subprocess.TimeoutExpired:
            continue
        if stop is signal.SIGTERM:
            time.sleep(0.2)              # its own children's turn to go, then SIGKILL any left


def kill_later(child: Child, delay: float, stop: threading.Event) -> None:
    """Fault injection: SIGKILL a child; the supervision then reports it as crashed."""
    if not stop.wait(delay) and child.exited() is None:
        print(f"hil up: injected kill of {child.label} (pid {child.pid})", flush=True)
        child.process.kill()


def wait_alive(run: Run, alive: Callable[[str, float], bool], child: Child) -> None:
    """Wait until ``alive(name, timeout)`` says ``child`` is up (on Zenoh: its liveliness
    token, ``hil.messaging.zenoh_api.ProcessWatch.wait_alive``), as :meth:`Run.wait_until`."""
    run.wait_until(child, lambda timeout: alive(child.name, timeout), "alive on Zenoh")
    if not run.stop.is_set():
        print(f"hil up: {child.label} ready (pid {child.pid})", flush=True)


def viz_summary(viz: Child) -> str | None:
    """The visualiser's closing summary ("N cycles in M batches, ..."), if it printed one."""
    lines = [line for line in viz.last_lines().splitlines() if "cycles in" in line]
    return lines[-1].strip().removeprefix("hil viz: ") if lines else None


def cpus_argument(chosen: set[int] | None) -> list[str]:
    """``--cpus`` for a child process (as :func:`parse_cpus` reads it); none for None."""
    return [f"--cpus={','.join(map(str, sorted(chosen)))}"] if chosen else []


def parse_cpus(text: str) -> set[int]:
    """The CPU numbers of a ``--cpus`` list ("1", "2,3"); ValueError if it is none."""
    return {int(part) for part in text.split(",")}


def end_with_parent_if_asked() -> None:
    """In a supervised child: SIGTERM this process (a clean stop) once its supervisor is
    gone, however it died."""
    parent = os.environ.get(PARENT_PID_VARIABLE, "")
    if not parent.isdigit():
        return

    def watch() -> None:
        while os.getppid() == int(parent):
            threading.Event().wait(0.2)
        os.kill(os.getpid(), signal.SIGTERM)
    threading.Thread(target=watch, name="end-with-parent", daemon=True).start()
