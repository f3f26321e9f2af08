"""Where and under which policy a real-time process' threads run: SCHED_FIFO for loops and
frame handling, a lower priority for side work, SCHED_IDLE for what must never take their
time, and the CPUs ``hil up`` gives each process."""

from __future__ import annotations

import os
import sys
import threading

#: SCHED_FIFO priority a real-time loop asks for (ros2_control's controller manager asks for
#: the same); 0 keeps the normal scheduler
REAL_TIME_PRIORITY = 50
#: SCHED_FIFO priority of a real-time process' other threads (its Zenoh and frame-handling
#: threads, all of a simulator's), just below its loop's (:func:`enter_real_time`)
IO_PRIORITY = REAL_TIME_PRIORITY - 1
#: SCHED_FIFO priority of a real-time process' side work (goals decoded, recordings encoded):
#: below its frame handling, which must preempt it (threads of one SCHED_FIFO priority do
#: not share a CPU: a first recording encoded on the controller's CPU held its frames for
#: cycles, docs/performance.md, "2026-12-06, later: figures from code comments"), above every
#: normal process (its GIL must not wait behind them)
SIDE_PRIORITY = 40
#: the interpreter's thread switch interval while a real-time loop runs (s; Python's default
#: is 5 ms): the longest a thread holding the GIL (decoding a large goal, say) keeps the loop
#: waiting for it once the loop wakes
REAL_TIME_SWITCH_INTERVAL = 200e-6


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
    (Zenoh's, python-can's, hil's own), and a short thread switch interval. Call it before
    opening Zenoh sessions or buses. Under the normal scheduler a process' frame handling
    waited behind any other runnable thread of the machine (the visualiser's, a
    neighbour's); sim and controller each on a CPU of their own answered a cycle's frames
    sooner at p99 than sharing two CPUs (docs/performance.md,
    "2026-12-06, later: figures from code comments"). Returns the scheduling, in words."""
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


def lock_step_cpus(cpus: set[int] | None = None) -> tuple[set[int] | None, set[int] | None,
                                                           set[int] | None]:
    """Where ``hil up --lock-step`` puts (sim, controller, visualiser): simulator and
    controller together on the last CPU this process may use, the visualiser on the others.
    In lock-step the two take turns, never run at once, and a hand-over within one CPU costs
    less than waking a process on another (an inter-processor interrupt, dear in a virtual
    machine): the ur3's demo ran faster that way on 2 vCPUs (docs/performance.md, "2026-11-29,
    afternoon: `hil up --lock-step` start-up and placement"). None: anywhere (a single CPU)."""
    usable = sorted(cpus if cpus is not None else os.sched_getaffinity(0))
    if len(usable) < 2:
        return None, None, None
    return {usable[-1]}, {usable[-1]}, set(usable[:-1])


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


def leave_background() -> bool:
    """Every thread of this process that runs under SCHED_IDLE back under the normal
    scheduler, for bounded work that must end soon (a stopped visualiser's last batches and
    its recording's flush): starved by a busy host, SCHED_IDLE threads left a SIGTERM
    unanswered for more than 30 s (seen in CI). Whether every such thread left it: Linux
    lets an unprivileged thread leave SCHED_IDLE only within its RLIMIT_NICE (0 by default,
    sched(7)), so without root or CAP_SYS_NICE it stays, and the work ends when the host
    lets it."""
    left = True
    for tid in map(int, os.listdir("/proc/self/task")):
        try:
            if os.sched_getscheduler(tid) == os.SCHED_IDLE:
                os.sched_setscheduler(tid, os.SCHED_OTHER, os.sched_param(0))
        except ProcessLookupError:
            continue                    # the thread ended meanwhile
        except PermissionError:
            left = False
    return left
