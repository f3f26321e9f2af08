"""Fault reset: after a drive fault the controller recovers on request, and only then."""

from __future__ import annotations

import threading
import time
import uuid

import can
import pytest

from hil.bus_config import load_bus_config
from hil.control_node import ControlNode
from hil.controllers import GoalRejected, GoalStatus, TrajectoryGoal, TrajectoryPoint
from hil.drives.core import Fault
from hil.hardware import CanHardwareInterface
from hil.messaging.zenoh_api import TrajectoryActionClient
from hil.simulator import Simulator
from hil.zenoh_session import ZenohSettings, session
from conftest import UR3_VIRTUAL, free_port


class ControlledBench:
    """The ur3 fixture: Simulator and ControlNode in this process, on a python-can virtual
    bus; the action client on the node's own Zenoh session (loopback)."""

    def __init__(self):
        self.config = load_bus_config(UR3_VIRTUAL)
        channel = f"hil-reset-{uuid.uuid4().hex[:8]}"
        self.sim_bus = can.Bus(interface="virtual", channel=channel)
        self.master_bus = can.Bus(interface="virtual", channel=channel)
        self.sim = Simulator(self.config, {"arm": self.sim_bus})
        self.sim.start()
        self.sim_thread = threading.Thread(target=self.sim.run, daemon=True)
        self.sim_thread.start()
        self.session = session(ZenohSettings(listen=(f"tcp/127.0.0.1:{free_port()}",)))
        self.hardware = CanHardwareInterface(self.config, {"arm": self.master_bus})
        self.node = ControlNode(self.hardware, self.session, self.config.cycle_hz)
        self.node_thread = threading.Thread(target=self.node.run, daemon=True)
        self.node_thread.start()
        self.client = TrajectoryActionClient(self.session, "ur3")
        assert self.client.wait_for_controller(30), "the control node did not come up"

    def fault(self, node_id: int, fault: Fault = Fault.FOLLOWING_ERROR) -> None:
        drive = next(d for d in self.sim.drives if d.node_id == node_id)
        with self.sim.lock:
            drive.core.raise_fault(fault)
            drive.after_update()                     # sends the EMCY, as a real drive would
        deadline = time.monotonic() + 5
        while not self.node.faults and time.monotonic() < deadline:
            time.sleep(0.01)
        assert self.node.faults, "the controller did not notice the fault"

    def move(self, joint: str, to: float, seconds: float = 0.5):
        goal_id = self.client.send_goal(TrajectoryGoal((joint,), (
            TrajectoryPoint(seconds, (to,), (0.0,)),)))
        return goal_id

    def close(self) -> None:
        self.client.close()
        self.node.stop()
        self.node_thread.join(10)
        self.sim.stop()
        self.sim_thread.join(5)
        self.sim.close()
        self.master_bus.shutdown()
        self.sim_bus.shutdown()


@pytest.fixture
def controlled():
    bench = ControlledBench()
    yield bench
    bench.close()


def test_reset_brings_a_faulted_drive_back_and_goals_are_accepted_again(controlled):
    controlled.fault(2)
    assert "drive node 2 (joint2)" in controlled.node.faults[0]
    assert "FAULT" in controlled.node.faults[0]
    with pytest.raises(GoalRejected, match="hardware is faulted"):
        controlled.move("joint2", 0.1)
    succeeded, message = controlled.client.reset_faults()
    assert succeeded, message
    assert all(axis.state == "OPERATION ENABLED" for axis in controlled.hardware.axes)
    goal_id = controlled.move("joint2", 0.1)
    result = controlled.client.wait_result(goal_id, 30)
    assert result.status is GoalStatus.SUCCEEDED, result


def test_reset_fails_naming_the_drive_while_it_stays_silent(controlled):
    silent = next(d for d in controlled.sim.drives if d.node_id == 3)
    silent.detach()                                  # no heartbeat, no TPDO from now on
    deadline = time.monotonic() + 5
    while not controlled.node.faults and time.monotonic() < deadline:
        time.sleep(0.01)
    succeeded, message = controlled.client.reset_faults()
    assert not succeeded
    assert "drive node 3 (joint3)" in message and "silent" in message
    with pytest.raises(GoalRejected, match="hardware is faulted"):
        controlled.move("joint1", 0.1)


def test_reset_without_a_fault_leaves_the_active_goal_running(controlled):
    goal_id = controlled.move("joint1", 0.2, seconds=1.0)
    assert controlled.client.reset_faults() == (True, "no fault to reset")
    result = controlled.client.wait_result(goal_id, 30)
    assert result.status is GoalStatus.SUCCEEDED, result
