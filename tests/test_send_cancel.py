"""`hil send` stopped mid-goal cancels its goal, as `ros2 action send_goal` does (ros2cli,
ros2action/verb/send_goal.py: its `finally` cancels a goal still accepted or executing)."""

from __future__ import annotations

import queue
import signal
import subprocess
import sys
import time

import pytest

from hil.bus_config import load_bus_config
from hil.cli import send
from hil.controllers import GoalResult, GoalStatus
from hil.messaging import cdr
from hil.messaging.keys import ACTION, key
from hil.realtime import LOCK_STEP
from hil.stack import running_stack
from conftest import ROOT

#: plant time (s) the test lets pass after the cancel: early in a 60 s goal of 1 rad,
#: joint2 moves about 10 mrad in it
AFTER = 2.0


@pytest.fixture
def sending():
    """A lock-step ur3 stack, and a function that starts `hil send` moving its joint2 1 rad
    in ``seconds`` (with extra arguments; ``launcher``: a ``python -c`` program that execs
    the rest): (the stack, the `hil send` process, a queue of the goals' results)."""
    config = load_bus_config(ROOT / "bus_config" / "ur3.yaml")
    with running_stack(config, LOCK_STEP) as stack:
        results: queue.Queue = queue.Queue()
        listener = stack.zenoh.declare_subscriber(
            f"{key('ur3', ACTION)}/result", lambda sample: results.put(cdr.result_from_msg(
                cdr.decode(sample.payload.to_bytes(), cdr.GOAL_RESULT))))
        started: list[subprocess.Popen] = []

        def send(seconds: int, *extra: str, launcher: str | None = None):
            prefix = [sys.executable] + (["-c", launcher] if launcher else [])
            started.append(subprocess.Popen(
                [*prefix, "-m", "hil", "send", "ur3", "--joint", "joint2", "--to",
                 "1.0", "--in", f"{seconds}s", "--connect", stack.zenoh_settings.listen[0], *extra],
                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True))
            return stack, started[-1], results

        yield send
        for process in started:
            if process.poll() is None:
                process.kill()
            process.communicate()
        listener.undeclare()


def assert_cancelled_and_still(stack, results: queue.Queue) -> None:
    """The goal ended CANCELED, and joint2 stays where it stopped while the plant goes on."""
    assert results.get(timeout=30).status is GoalStatus.CANCELED
    stopped_at, now = joint2(stack), stack.sim.now()
    while stack.sim.now() < now + AFTER:            # lock-step: the plant goes on
        time.sleep(0.05)
    assert joint2(stack) == pytest.approx(stopped_at, abs=1e-3)


def joint2(stack) -> float:
    with stack.sim.lock:
        return float(stack.sim.plant.joint_positions()[1])


#: `hil send` started with SIGINT ignored, as a shell starts a background job and as a test
#: run's worker once left it (inherited through exec): it ran its goal to the end on SIGINT
IGNORING_SIGINT = ("import os, signal, sys; signal.signal(signal.SIGINT, signal.SIG_IGN); "
                   "os.execv(sys.executable, [sys.executable, *sys.argv[1:]])")


@pytest.mark.parametrize("stop, status, parent", [
    (signal.SIGINT, 130, None), (signal.SIGINT, 130, IGNORING_SIGINT),
    (signal.SIGTERM, 143, None)], ids=["SIGINT", "SIGINT-ignored-before", "SIGTERM"])
def test_a_stopped_send_cancels_its_goal_and_the_arm_stops(sending, stop, status, parent):
    """Issue 64: Ctrl-C on `hil send` exited 130 and the goal moved the arm on to its
    target. Stopped at its first feedback, it says it cancels, exits 128 + the signal, the
    goal ends CANCELED and joint2 stays where it stopped. (CI runs failed here now and then
    with "not cancelled" and a Zenoh close that timed out: the handler's exception, raised
    wherever the main thread was, could leave a queue's lock held that Zenoh's receiving
    thread needed; the handlers only note the signal now.)"""
    stack, send, results = sending(60, launcher=parent)
    lines = []
    for line in send.stdout:                  # the goal runs: its first feedback
        lines.append(line)
        if "error" in line:
            break
    assert any("accepted" in line for line in lines), "".join(lines)
    send.send_signal(stop)
    out, err = send.communicate(timeout=60)
    assert send.returncode == status, out + err
    assert "stopped: cancelling goal" in err and "canceled" in err, out + err
    assert_cancelled_and_still(stack, results)


def test_a_send_that_gives_up_waiting_cancels_its_goal(sending):
    """The same defect beside it: `hil send --timeout` gave up on the result and left the
    goal running. A 600 s goal (lock-step runs nowhere near 600 times real time) and a 1 s
    timeout: it says it cancels, exits 1, the goal ends CANCELED."""
    stack, send, results = sending(600, "--timeout", "1s")
    out, err = send.communicate(timeout=120)
    assert send.returncode == 1, out + err
    assert "no result: cancelling goal" in err and "canceled" in err, err
    assert_cancelled_and_still(stack, results)


class _EndedGoalClient:
    """A client whose goal ended (aborted) just before its cancel arrived."""

    def cancel(self, goal_id: str) -> bool:
        return False

    def wait_result(self, goal_id: str, timeout: float):
        return GoalResult(GoalStatus.ABORTED, -4, "joint2 left its path tolerance")


def test_a_cancel_that_finds_its_goal_ended_says_how_it_ended(capsys):
    """A stopped `hil send` whose goal ended as the cancel went out says how it ended (its
    result), not only that it was not cancelled."""
    send._cancel(_EndedGoalClient(), "0123456789abcdef", (TimeoutError,), "stopped")
    err = capsys.readouterr().err
    assert "goal 01234567 not cancelled: the controller no longer runs it (it had ended " \
           "aborted, error_code -4 (joint2 left its path tolerance))" in err, err
