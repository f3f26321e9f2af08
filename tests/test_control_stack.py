"""The controller process with `hil sim` and a client, as separate processes over Zenoh."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from hil.bench.settings import with_feed_forward
from hil.bench.tracking import tracking
from hil.bus_config import load_bus_config
from hil.controllers.goal import PREEMPTED
from hil.controllers import GoalRejected, GoalStatus, TrajectoryGoal, TrajectoryPoint
from hil.messaging import cdr
from hil.messaging.zenoh_api import ControllerGone, TrajectoryActionClient, key
from hil.zenoh_session import ZenohSettings, close, session
from conftest import ROOT, free_port, socketcan_missing, ur3_at_100hz

#: judged against the host's stalls (tests/host_stalls.py): the stacks run in real time, as
#: separate processes
pytestmark = pytest.mark.real_time


#: bus configs whose robot is not named like the config
ROBOT_OF = {"pigot_mixed": "pigot"}


class ProcessStack:
    """`hil sim` and `hil control` (or `hil control --fake`) on one loopback port, for
    bus_config/<name>.yaml (or ``config``); real time unless ``lock_step``."""

    def __init__(self, name: str, fake: bool = False, can: str = "zenoh",
                 lock_step: bool = False, config: Path | None = None):
        robot = ROBOT_OF.get(name, name)
        self.robot = robot
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        config = str(config or ROOT / "bus_config" / f"{name}.yaml")
        # SocketCAN: each bus of the config on its own vcan (created by tools/uml_run.py)
        transport = ["--interface", "socketcan", "--channel", "arm=vcan0",
                     "--channel", "wrist=vcan1"] if can == "socketcan" else []
        transport += ["--lock-step"] if lock_step else []
        self.sim = self.control = self.session = self.client = self._subscriber = None
        try:
            self._start(config, fake, transport)
        except BaseException:        # a process that did not come up: end those that did
            self.close()
            raise

    def _start(self, config: str, fake: bool, transport: list[str]) -> None:
        if not fake:
            self.sim = self._spawn(["sim", config, "--listen", self.endpoint,
                                    "--status-period", "0", *transport], "hil sim:")
            self.control = self._spawn(["control", config, "--connect", self.endpoint,
                                        *transport], "hil control:")
        else:
            self.control = self._spawn(["control", config, "--fake", "--listen", self.endpoint],
                                       "hil control:")
        self.settings = ZenohSettings(connect=(self.endpoint,))
        self.session = session(self.settings)
        self.client = TrajectoryActionClient(self.session, self.robot)
        assert self.client.wait_for_controller(30), "controller not alive on Zenoh"
        self.states: list = []
        self._subscriber = self.session.declare_subscriber(
            key(self.robot, "joint_states"),
            lambda s: self.states.append(cdr.decode(s.payload.to_bytes(), cdr.JOINT_STATE)))

    @staticmethod
    def _spawn(args, banner):
        process = subprocess.Popen([sys.executable, "-m", "hil", *args], stdout=subprocess.PIPE,
                                   stderr=subprocess.PIPE, text=True)
        line = process.stdout.readline()
        if banner not in line:
            process.kill()
            raise AssertionError(f"{args[0]} did not start: {line}{process.stderr.read()}")
        return process

    def joint_state(self) -> dict[str, float]:
        deadline = time.monotonic() + 2
        count = len(self.states)
        while len(self.states) == count and time.monotonic() < deadline:
            time.sleep(0.01)
        last = self.states[-1]
        return dict(zip(last.name, last.position))

    def close(self) -> None:
        if self._subscriber is not None:
            self._subscriber.undeclare()
        if self.client is not None:
            self.client.close()
        if self.session is not None:
            close(self.settings)
        for process in (self.control, self.sim):
            if process is not None and process.poll() is None:
                process.send_signal(signal.SIGTERM)
        for process in (self.control, self.sim):
            if process is not None:
                try:
                    process.communicate(timeout=20)
                except subprocess.TimeoutExpired:
                    process.kill()
                    process.communicate()


# over SocketCAN the mixed pigot alone (two vcans, CiA 402 and MIT drives together), a stack
# taking minutes inside User-Mode Linux; the pigot's demo runs over SocketCAN in test_up
@pytest.fixture(params=[("ur3", "zenoh"), ("pigot", "zenoh"), ("pigot_mixed", "zenoh"),
                        pytest.param(("pigot_mixed", "socketcan"),
                                     marks=pytest.mark.socketcan)],
                ids=lambda p: f"{p[0]}-{p[1]}")
def stack(request):
    robot, can = request.param
    if can == "socketcan":
        missing = socketcan_missing()
        if missing:
            pytest.skip(missing)
    # lock-step: two real-time processes on a shared 2-core machine (or under User-Mode
    # Linux) now and then miss answers and rightly fault, which is not what this pins; real
    # time across processes is ur3_stack's, and the in-process stacks'
    made = ProcessStack(robot, can=can, lock_step=True)
    yield made
    made.close()


@pytest.fixture
def ur3_stack(tmp_path):
    # real time as separate processes, at 100 Hz (see ur3_at_100hz): these tests pin cancel
    # and kill behaviour, not the scheduler
    path = ur3_at_100hz(tmp_path)
    made = ProcessStack("ur3", config=path)
    yield made
    made.close()


@pytest.fixture
def fake_stack():
    made = ProcessStack("ur3", fake=True)
    yield made
    made.close()


MOVES = {
    "ur3": TrajectoryGoal(("joint1", "joint2", "joint3"), (
        TrajectoryPoint(1.0, (0.2, -0.3, 0.4)),
        TrajectoryPoint(2.0, (0.4, -0.5, 0.8), (0.0, 0.0, 0.0)))),
    # the brake-less pigot arm hangs on arm_rot_2's limit (1.571) before the controller
    # enables it; lift it part of the way
    "pigot": TrajectoryGoal(("arm_rot_1", "arm_rot_2", "finger_pri_1"), (
        TrajectoryPoint(1.0, (0.3, 1.3, 0.01)),
        TrajectoryPoint(2.0, (0.5, 1.1, 0.02), (0.0, 0.0, 0.0)))),
}


def run_goal(stack, goal, timeout=120.0):
    feedback = []
    goal_id = stack.client.send_goal(goal)
    result = stack.client.wait_result(goal_id, timeout, feedback.append)
    return result, feedback


def test_multi_point_trajectory_succeeds_on_the_simulated_robot(stack):
    goal = MOVES[stack.robot]
    result, feedback = run_goal(stack, goal)
    assert result.status is GoalStatus.SUCCEEDED, result
    assert feedback, "no feedback arrived"
    state = stack.joint_state()
    for name, target in zip(goal.joint_names, goal.points[-1].positions):
        assert state[name] == pytest.approx(target, abs=0.02), name
    if stack.robot == "pigot":     # the mimic finger is published, following its leader
        assert state["finger_pri_2"] == pytest.approx(state["finger_pri_1"], abs=1e-9)


def test_fake_mode_serves_the_same_api_without_a_sim(fake_stack):
    result, feedback = run_goal(fake_stack, MOVES["ur3"])
    assert result.status is GoalStatus.SUCCEEDED and feedback
    # the echo lags one cycle: the states published right after the result may still move
    deadline = time.monotonic() + 2
    while abs(fake_stack.joint_state()["joint3"] - 0.8) > 1e-6 and time.monotonic() < deadline:
        pass
    assert fake_stack.joint_state()["joint3"] == pytest.approx(0.8, abs=1e-6)
    with pytest.raises(GoalRejected, match="unknown joint 'joint7'"):
        fake_stack.client.send_goal(TrajectoryGoal(("joint7",), (TrajectoryPoint(1, (0.1,)),)))


def test_preemption_aborts_the_first_goal_with_its_reason(fake_stack):
    first = fake_stack.client.send_goal(TrajectoryGoal(("joint1",), (TrajectoryPoint(3.0, (1.0,)),)))
    time.sleep(0.5)
    second = fake_stack.client.send_goal(TrajectoryGoal(("joint1",), (TrajectoryPoint(1.0, (0.0,)),)))
    result = fake_stack.client.wait_result(first, 5)
    assert second and result.status is GoalStatus.ABORTED
    assert result.error_string == PREEMPTED          # the JTC's own words
    assert fake_stack.client.wait_result(second, 5).status is GoalStatus.SUCCEEDED


def test_cancel_holds_position_for_a_second(ur3_stack):
    goal_id = ur3_stack.client.send_goal(TrajectoryGoal(("joint2",), (TrajectoryPoint(3.0, (0.9,)),)))
    time.sleep(1.2)
    assert ur3_stack.client.cancel(goal_id)
    assert ur3_stack.client.wait_result(goal_id, 5).status is GoalStatus.CANCELED
    time.sleep(0.2)
    held = ur3_stack.joint_state()["joint2"]
    assert 0.05 < held < 0.85
    samples = []
    end = time.monotonic() + 1.0
    while time.monotonic() < end:
        samples.append(ur3_stack.joint_state()["joint2"])
    assert np.max(np.abs(np.array(samples) - held)) < 0.02


def test_rejections_come_back_with_reasons(fake_stack):
    client = fake_stack.client
    cases = {
        "unknown joint 'wrist'": TrajectoryGoal(("wrist",), (TrajectoryPoint(1, (0.1,)),)),
        "outside its limits": TrajectoryGoal(("joint1",), (TrajectoryPoint(1, (7.0,)),)),
        "is not after": TrajectoryGoal(("joint1",), (TrajectoryPoint(1, (0.1,)),
                                                     TrajectoryPoint(0.5, (0.2,)))),
        "velocity limit": TrajectoryGoal(("joint1",), (TrajectoryPoint(0.1, (1.0,)),)),
        "is nan": TrajectoryGoal(("joint1",), (TrajectoryPoint(1, (float("nan"),)),)),
    }
    for words, goal in cases.items():
        with pytest.raises(GoalRejected, match=words):
            client.send_goal(goal)


def test_malformed_goal_payload_gets_an_error_and_the_server_lives_on(fake_stack):
    for junk in (b"", b"\x00\x01\x00\x00garbage", bytes(range(200))):
        with pytest.raises(GoalRejected, match="malformed"):
            fake_stack.client.send_raw(junk)
    result, _ = run_goal(fake_stack, MOVES["ur3"])
    assert result.status is GoalStatus.SUCCEEDED


def test_killed_sim_aborts_the_goal_naming_the_drive(ur3_stack):
    goal_id = ur3_stack.client.send_goal(TrajectoryGoal(("joint1",), (TrajectoryPoint(4.0, (0.8,)),)))
    time.sleep(1.0)
    ur3_stack.sim.kill()
    killed = time.monotonic()
    result = ur3_stack.client.wait_result(goal_id, 5)
    detected = time.monotonic() - killed
    assert result.status is GoalStatus.ABORTED
    assert "drive node" in result.error_string and "silent" in result.error_string
    print(f"killed sim detected and goal aborted after {detected * 1e3:.0f} ms")
    assert detected < 3 * 0.1, f"detected after {detected:.3f} s (3 heartbeats: 0.3 s)"
    with pytest.raises(GoalRejected, match="faulted"):
        ur3_stack.client.send_goal(MOVES["ur3"])


def test_killed_controller_lets_the_drives_quick_stop_by_watchdog(ur3_stack):
    import can
    import canopen
    goal_id = ur3_stack.client.send_goal(TrajectoryGoal(("joint2",), (TrajectoryPoint(3.0, (0.8,)),)))
    time.sleep(1.0)
    ur3_stack.control.kill()
    try:
        result = ur3_stack.client.wait_result(goal_id, 5)
    except ControllerGone:
        pass
    else:
        pytest.fail(f"the goal ended before the controller was killed: {result}")
    bus = can.Bus(interface="zenoh", channel="ur3/arm", connect=[ur3_stack.endpoint])
    network = canopen.Network(bus)
    network.notifier = can.Notifier(bus, network.listeners, 0.1)
    try:
        node = canopen.RemoteNode(2, str(ROOT / "bus_config" / "cia402_drive.eds"))
        network.add_node(node)
        time.sleep(0.5)
        assert node.sdo[0x6041].raw & 0x6F == 0x07           # QUICK STOP ACTIVE
        first = node.sdo[0x6064].raw
        time.sleep(0.5)
        assert abs(node.sdo[0x6064].raw - first) < 200        # standing still
    finally:
        network.notifier.stop(1)
        bus.shutdown()


def test_hil_send_exits_zero_on_success_and_one_on_rejection(fake_stack, tmp_path):
    base = [sys.executable, "-m", "hil", "send", "ur3", "--connect", fake_stack.endpoint]
    ok = subprocess.run(base + ["--joint", "joint2", "--to", "0.4", "--in", "500ms"],
                        capture_output=True, text=True, timeout=60)
    assert ok.returncode == 0, ok.stderr
    assert "accepted" in ok.stdout and "succeeded, error_code 0" in ok.stdout
    trajectory = tmp_path / "t.yaml"
    trajectory.write_text("joint_names: [joint1]\npoints:\n  - {positions: [5.0], "
                          "time_from_start: 1.0}\n")
    rejected = subprocess.run(base + [str(trajectory)], capture_output=True, text=True,
                              timeout=60)
    assert rejected.returncode == 1
    assert "position 5 is outside its limits" in rejected.stderr
    broken = tmp_path / "b.yaml"
    broken.write_text("points: 3\n")
    bad = subprocess.run(base + [str(broken)], capture_output=True, text=True, timeout=60)
    assert bad.returncode == 1 and "is not a trajectory" in bad.stderr
    assert "Traceback" not in bad.stderr + rejected.stderr


@pytest.mark.parametrize("robot", ["ur3", "pigot"])
def test_velocity_feed_forward_tracks_at_least_as_close_as_the_ideal_servo(robot):
    # lock-step: the same cycles every run. Positions alone trail the reference by the
    # interpolation's cycle; the trajectory's velocity as 0x60B1 takes that away
    config = load_bus_config(ROOT / "bus_config" / f"{robot}.yaml")
    plain, fed = tracking(config), tracking(with_feed_forward(config))
    assert plain["result"] == fed["result"] == "succeeded"
    assert fed["rms"] < 0.5 * plain["rms"], (fed["rms"], plain["rms"])
    assert fed["rms"] <= 1.1 * fed["ideal_servo_rms"], (fed["rms"], fed["ideal_servo_rms"])
