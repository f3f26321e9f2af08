"""Fault reset: after a drive fault the controller recovers on request, and only then."""

from __future__ import annotations

import threading
import time

import pytest

from hil.can.faults import FrameFault
from hil.controllers import HARDWARE_FAULT, GoalRejected, GoalStatus
from hil.hardware import FaultKind
from hil.messaging.zenoh_api import RunSubscriber

#: judged against the host's stalls (tests/host_stalls.py): faults and silences are judged on
#: the controller's clock
pytestmark = pytest.mark.real_time


def test_reset_brings_a_faulted_drive_back_and_goals_are_accepted_again(controlled):
    controlled.fault(2)
    fault = controlled.node.faults[0]
    assert (fault.kind, fault.bus, fault.node_id, fault.joints) == (
        FaultKind.FAULT, "arm", 2, ("joint2",))
    assert fault.code == 0x8611 and "drive node 2 (joint2)" in str(fault)
    with pytest.raises(GoalRejected, match="hardware is faulted") as refused:
        controlled.move("joint2", 0.1)
    assert refused.value.error_code == HARDWARE_FAULT           # the server's code, kept
    succeeded, message = controlled.client.reset_faults()
    assert succeeded, message
    assert all(axis.state == "OPERATION ENABLED" for axis in controlled.hardware.axes)
    goal_id = controlled.move("joint2", 0.1)
    result = controlled.client.wait_result(goal_id, 30)
    assert result.status is GoalStatus.SUCCEEDED, result


def test_a_reset_whose_first_answers_come_late_still_brings_the_drives_back(controlled):
    # answers a cycle late (over the reply timeout) are sampled before the reset's commands
    # reached the drives: the FAULT and QUICK STOP they show are what the reset walks out of
    controlled.fault(2)
    controlled.sim_bus.add(FrameFault("delay", "arm", 1.0, 1.5 / controlled.config.cycle_hz))
    succeeded, message = controlled.client.reset_faults()
    assert succeeded, message
    assert controlled.sim_bus.injected["delay"] > 0


def test_reset_fails_naming_the_drive_while_its_fault_persists(controlled):
    controlled.fault(2)
    done = threading.Event()

    def fault_again():                  # the drive faults again whenever it is reset
        while not done.wait(0.005):
            controlled.sim.raise_fault("arm", 2)

    refaulting = threading.Thread(target=fault_again)
    refaulting.start()
    try:
        succeeded, message = controlled.client.reset_faults()
    finally:
        done.set()
        refaulting.join()
    assert not succeeded
    assert "drive node 2 (joint2)" in message and "FAULT" in message, message


def test_reset_fails_naming_the_drive_while_it_stays_silent(controlled):
    controlled.sim.silence("arm", 3)                 # no heartbeat, no TPDO from now on
    deadline = time.monotonic() + 5
    while not controlled.node.faults and time.monotonic() < deadline:
        time.sleep(0.01)
    succeeded, message = controlled.client.reset_faults()
    assert not succeeded
    assert "drive node 3 (joint3)" in message and "silent" in message
    with pytest.raises(GoalRejected, match="hardware is faulted"):
        controlled.move("joint1", 0.1)


def test_a_drive_that_restarted_is_named_and_a_reset_configures_it_again(controlled):
    controlled.sim.restart("arm", 2)            # a power cycle: boots unconfigured
    deadline = time.monotonic() + 5
    while not controlled.node.faults and time.monotonic() < deadline:
        time.sleep(0.01)
    rebooted = [f for f in controlled.node.faults if f.kind is FaultKind.REBOOTED]
    assert [(f.bus, f.node_id) for f in rebooted] == [("arm", 2)], controlled.node.faults
    assert "booted again" in str(rebooted[0])
    succeeded, message = controlled.client.reset_faults()
    assert succeeded, message
    assert all(axis.state == "OPERATION ENABLED" for axis in controlled.hardware.axes)
    result = controlled.client.wait_result(controlled.move("joint2", 0.1), 30)
    assert result.status is GoalStatus.SUCCEEDED, result


def test_reset_without_a_fault_leaves_the_active_goal_running(controlled):
    goal_id = controlled.move("joint1", 0.2, seconds=1.0)
    assert controlled.client.reset_faults() == (True, "no fault to reset")
    result = controlled.client.wait_result(goal_id, 30)
    assert result.status is GoalStatus.SUCCEEDED, result


def test_a_fault_and_its_reset_are_published_as_diagnostics_on_the_controllers_clock(
        controlled):
    heard, arrived = [], threading.Condition()

    def hear(diagnostic):
        with arrived:
            heard.append(diagnostic)
            arrived.notify_all()

    subscriber = RunSubscriber(controlled.zenoh, "ur3", lambda batch: None,
                               lambda wall, sim: None, pytest.fail, hear)
    try:
        before = controlled.node.clock()
        controlled.fault(2)
        succeeded, message = controlled.client.reset_faults()
        assert succeeded, message
        with arrived:
            assert arrived.wait_for(lambda: len(heard) >= 2, timeout=10), heard
    finally:
        subscriber.close()
    fault, reset = heard
    assert (fault.level, fault.message) == ("ERROR", str(controlled.node.faults[0]))
    assert dict(fault.values) == {"kind": "fault", "bus": "arm", "node_id": "2",
                                  "joints": "joint2", "code": "0x8611"}
    assert fault.hardware_id == "ur3"
    assert before <= fault.control_time <= reset.control_time <= controlled.node.clock()
    assert reset.level == "OK" and "every drive follows commands again" in reset.message



def test_send_says_to_reset_after_a_drive_fault(capsys):
    import argparse

    from hil.cli.send import _hint_after_a_fault

    _hint_after_a_fault(HARDWARE_FAULT, argparse.Namespace(ros=False, robot="ur3"))
    said = capsys.readouterr().err
    assert "`hil reset ur3` clears the drives' faults" in said and "--lock-step" in said
    _hint_after_a_fault(0, argparse.Namespace(ros=False, robot="ur3"))
    assert capsys.readouterr().err == ""
