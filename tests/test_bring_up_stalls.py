"""A real-time bring-up that fails while the bench itself stalled is told as the bench's, with
the stalls and exit status 3; one that fails without such a stall stays the drive's. The
stalls are given, or made on purpose (this thread holding the interpreter): nothing here
judges the host's timing."""

from __future__ import annotations

import sys
import time

import pytest

import hil.control_node.bring_up as bring_up
from hil.control_node.bring_up import BRING_UP_STALL, BringUpStalled, judged_bring_up
from hil.errors import BootTimeout, BringUpError, HilError
from hil.realtime.stalls import BENCH_STALL_STATUS, Stall

NOT_ANSWERED = "drive node 1 (joint1) on bus 'arm' does not answer SDO: No SDO response"


def _fails() -> None:
    raise HilError.single(NOT_ANSWERED, hint="is the drive powered and on this bus?")


@pytest.fixture
def short_grace(monkeypatch):
    monkeypatch.setattr(bring_up, "GRACE", 0.2)


class _Reports:
    """Stalls published and heard back, as the controller's Zenoh path does."""

    def __init__(self, *given: Stall):
        self.pending = list(given)

    def publish(self, stall: Stall) -> None:
        self.pending.append(stall)

    def heard(self) -> list[Stall]:
        heard, self.pending = self.pending, []
        return heard


def test_a_bring_up_that_fails_during_a_stall_of_the_simulator_is_the_benchs(short_grace):
    reports = _Reports(Stall("sim", time.time() - 0.1, 0.4))
    with pytest.raises(BringUpStalled) as raised:
        judged_bring_up(_fails, reports.publish, reports.heard, lambda: False)
    assert raised.value.exit_status == BENCH_STALL_STATUS == 3
    text = str(raised.value)
    assert text.startswith(f"error: {NOT_ANSWERED}\n")
    assert "is the drive powered" not in text           # the hint sends the user to the drive
    assert "the bench itself stalled during the bring-up: the simulator stalled 400 ms" in text
    assert "the bench broke real time, the drive need not have failed" in text


def test_a_boot_timeout_told_as_the_benchs_is_still_a_bring_up_error_of_its_drives(short_grace):
    """hil.errors: a user's test catches a bring-up that failed as BringUpError, whether or not
    the bench stalled meanwhile; the stalled one keeps the failure's bus, node and drives."""
    drive = "drive node 1 (joint1) on bus 'arm'"

    def boot_timeout() -> None:
        raise BootTimeout.single(f"{drive}: not heard within 3 s after reset", timeout=3.0,
                                 drives=(drive,), bus="arm", node=1)

    reports = _Reports(Stall("sim", time.time() - 0.1, 0.4))
    with pytest.raises(BringUpError) as raised:
        judged_bring_up(boot_timeout, reports.publish, reports.heard, lambda: False)
    assert isinstance(raised.value, BringUpStalled)
    assert raised.value.exit_status == BENCH_STALL_STATUS
    assert (raised.value.drives, raised.value.bus, raised.value.node) == ((drive,), "arm", 1)


def test_a_stall_reported_after_the_failure_within_the_grace_still_explains_it(short_grace):
    reports = _Reports()
    began = time.time()

    def heard() -> list[Stall]:          # the simulator's report, once its stall has ended
        return [Stall("sim", began, 0.3)] if time.time() > began + 0.1 else []

    with pytest.raises(BringUpStalled):
        judged_bring_up(_fails, reports.publish, heard, lambda: False)


@pytest.mark.parametrize("stall", [
    pytest.param(lambda now: Stall("sim", now - 0.1, BRING_UP_STALL / 2), id="too short"),
    pytest.param(lambda now: Stall("transport", now - 10.0, 0.5), id="before the bring-up"),
    pytest.param(lambda now: None, id="none"),
])
def test_a_bring_up_that_fails_without_a_long_stall_meanwhile_stays_the_drives(
        short_grace, stall):
    made = stall(time.time())
    reports = _Reports(*([made] if made else []))
    with pytest.raises(HilError) as raised:
        judged_bring_up(_fails, reports.publish, reports.heard, lambda: False)
    assert type(raised.value) is HilError and raised.value.exit_status == 1
    assert "is the drive powered" in str(raised.value)


def test_the_controllers_own_stall_during_the_bring_up_is_found_and_published(short_grace):
    reports = _Reports()

    def holds_the_interpreter_then_fails() -> None:
        # the watch thread cannot run while this one keeps the interpreter: a stall of
        # the controller's process as a descheduled one would be
        previous = sys.getswitchinterval()
        sys.setswitchinterval(5.0)
        try:
            end = time.perf_counter() + 3 * BRING_UP_STALL
            while time.perf_counter() < end:
                pass
        finally:
            sys.setswitchinterval(previous)
        _fails()

    with pytest.raises(BringUpStalled) as raised:
        judged_bring_up(holds_the_interpreter_then_fails, reports.publish, reports.heard,
                        lambda: False)
    own, = raised.value.stalls
    assert own.process == "control" and own.length >= 2 * BRING_UP_STALL
    assert "the controller stalled" in str(raised.value)


def test_a_bring_up_that_succeeds_or_is_stopped_is_not_judged(short_grace):
    reports = _Reports(Stall("sim", time.time(), 1.0))
    assert judged_bring_up(lambda: "feedback", reports.publish, reports.heard,
                           lambda: False) == "feedback"
    with pytest.raises(HilError) as raised:     # Ctrl-C while waiting: not a failure to judge
        judged_bring_up(_fails, reports.publish, reports.heard, lambda: True)
    assert type(raised.value) is HilError
