"""Controllers listed and switched as ros2_control's controller_manager does
(controller_manager.cpp, jazzy: switch_controller_cb), forward command controllers, and a
user's controller_manager YAML running (tests/controllers: Universal Robots' own, unchanged;
how such files are read: tests/test_controller_files.py)."""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from hil.bus_config import load_bus_config
from hil.controllers import (
    GoalRejected, GoalStatus, JointTolerance, TrajectoryGoal, TrajectoryPoint,
)
from hil.controllers.config import (
    DEFAULT_GOAL_TOLERANCE, ForwardSpec, hil_controllers,
)
from hil.controllers.goal import DEACTIVATED
from hil.controllers.manager import ControllerManager, Strictness, SwitchResult
from hil.messaging import cdr
from hil.messaging.controller_manager import ControllerManagerClient, switch_response
from hil.messaging.zenoh_api import TrajectoryActionClient
from hil.realtime import LOCK_STEP
from hil.stack import running_stack
from hil.zenoh_session import ZenohSettings, close, session
from conftest import free_port

HERE = Path(__file__).parent
UR_BENCH = HERE / "controllers" / "ur3_with_ur_controllers.yaml"
JTC, POSITION, VELOCITY = ("joint_trajectory_controller", "forward_position_controller",
                           "forward_velocity_controller")
PERIOD = 0.01


@pytest.fixture
def manager(ur3) -> ControllerManager:
    joints = tuple(j.name for j in ur3.driven_joints)
    made = ControllerManager.from_config(ur3, joints,
                                         hil_controllers(joints, DEFAULT_GOAL_TOLERANCE), PERIOD)
    made.update(0.0, np.zeros(6), np.zeros(6))           # the first cycle activates the JTC
    return made


def states(manager):
    return {info.name: info.state for info in manager.list()}


def test_the_list_names_each_controller_its_state_type_and_claims(manager):
    listed = {info.name: info for info in manager.list()}
    assert states(manager) == {JTC: "active", POSITION: "inactive", VELOCITY: "inactive"}
    assert listed[JTC].type == "joint_trajectory_controller/JointTrajectoryController"
    assert listed[JTC].claimed_interfaces[:2] == ("joint1/position", "joint1/velocity")
    assert listed[POSITION].claimed_interfaces == ()
    assert listed[POSITION].required_command_interfaces[0] == "joint1/position"


def test_required_state_interfaces_are_each_controllers_own(ur3):
    """list_controllers_srv_cb lists state_interface_configuration(): the JTC's is each of its
    joints with each of its state_interfaces (joint_trajectory_controller.cpp), a forward
    controller's is NONE, so it requires no state interface (forward_controllers_base.cpp)."""
    joints = tuple(j.name for j in ur3.driven_joints)
    config = hil_controllers(joints, DEFAULT_GOAL_TOLERANCE)
    config = replace(config, trajectory=replace(config.trajectory, state_interfaces=("position",)))
    listed = {info.name: info for info in
              ControllerManager.from_config(ur3, joints, config, PERIOD).list()}
    assert listed[JTC].required_state_interfaces == tuple(f"{j}/position" for j in joints)
    assert listed[POSITION].required_state_interfaces == ()
    assert listed[VELOCITY].required_state_interfaces == ()


def test_a_switch_onto_a_claimed_interface_fails_in_either_strictness(manager):
    """check_for_interfaces_availability_to_activate: an interface another active controller
    keeps, or one another controller of the same switch takes, is not available; the
    switch fails whatever its strictness, and nothing is switched."""
    for strictness in Strictness:
        result = manager.switch([POSITION], [], strictness)
        assert result == SwitchResult(False, f"Unable to activate controller '{POSITION}' "
                                      "since the command interface 'joint1/position' is "
                                      "currently claimed by another controller.")
    assert states(manager) == {JTC: "active", POSITION: "inactive", VELOCITY: "inactive"}


def test_two_controllers_of_one_switch_never_take_the_same_interface(ur3):
    """check_for_interfaces_availability_to_activate: "... will be used by another controller
    that is being activated." in either strictness; nothing is switched."""
    joints = tuple(j.name for j in ur3.driven_joints)
    config = hil_controllers(joints, DEFAULT_GOAL_TOLERANCE)
    second = ForwardSpec("joint1_position_controller", config.forwards[0].type, joints[:1],
                         "position")
    manager = ControllerManager.from_config(
        ur3, joints, replace(config, forwards=(*config.forwards, second)), PERIOD)
    manager.update(0.0, np.zeros(6), np.zeros(6))
    for strictness in Strictness:
        result = manager.switch([POSITION, second.name], [JTC], strictness)
        assert result == SwitchResult(False, f"Unable to activate controller '{second.name}' "
                                      "since the command interface 'joint1/position' will be "
                                      "used by another controller that is being activated.")
        assert manager.is_active(JTC) and not manager.is_active(POSITION)


UNKNOWN = "nonexistent_controller"
STRICT, BEST_EFFORT = Strictness.STRICT, Strictness.BEST_EFFORT


@pytest.mark.parametrize("ok, strictness, activate, deactivate", [
    (True, STRICT, [], []),
    (True, BEST_EFFORT, [], []),
    (False, STRICT, [UNKNOWN], []),
    (False, BEST_EFFORT, [UNKNOWN], []),
    (False, STRICT, [], [UNKNOWN]),
    (False, BEST_EFFORT, [], [UNKNOWN]),
    (False, STRICT, [UNKNOWN], [UNKNOWN]),
    (False, BEST_EFFORT, [UNKNOWN], [UNKNOWN]),
    (False, STRICT, [UNKNOWN], [JTC]),
    (False, BEST_EFFORT, [UNKNOWN], [JTC]),
    (False, STRICT, [POSITION, UNKNOWN], [JTC]),
    (True, BEST_EFFORT, [POSITION, UNKNOWN], [JTC]),
    (True, BEST_EFFORT, [UNKNOWN, POSITION], [JTC]),
    (False, STRICT, [POSITION], [JTC, UNKNOWN]),
    (True, BEST_EFFORT, [POSITION], [JTC, UNKNOWN]),
])
def test_each_switch_outcome_with_unknown_controllers_is_controller_managers(
        manager, ok, strictness, activate, deactivate):
    """test_load_controller.cpp (SwitchTest, EmptyListOrNonExistentTest) and
    test_controller_manager_srvs.cpp (switch_controller_failure_behaviour_on_unknown_controller):
    empty lists are OK; a list naming only unknown controllers is an ERROR in either
    strictness (switch_controller_cb: "not a critical error" only while another of the
    list exists), and so is STRICT with any unknown one. An ERROR switches nothing."""
    before = states(manager)
    result = manager.switch(activate, deactivate, strictness)
    assert result.ok is ok, result.message
    if not ok:
        assert "no controller with this name exists" in result.message
        assert states(manager) == before
    elif activate:
        assert states(manager) == {JTC: "inactive", POSITION: "active", VELOCITY: "inactive"}


def test_an_active_controller_to_activate_or_an_inactive_one_to_deactivate(manager):
    """switch_controller_cb: STRICT aborts ("Controller with name '...' is already active.",
    "... can not be deactivated since it is not active."); BEST_EFFORT drops it and, with
    nothing left, answers OK "After checking the controllers, no controllers need to be
    activated or deactivated." (test_controller_manager.cpp, controller_lifecycle)."""
    assert manager.switch([JTC], [], STRICT) == SwitchResult(
        False, f"Controller with name '{JTC}' is already active.")
    assert manager.switch([], [POSITION], STRICT) == SwitchResult(
        False, f"Controller with name '{POSITION}' can not be deactivated since it is not "
               "active.")
    nothing = SwitchResult(True, "After checking the controllers, no controllers need to be "
                                 "activated or deactivated.")
    assert manager.switch([JTC], [], BEST_EFFORT) == nothing
    assert manager.switch([], [POSITION], BEST_EFFORT) == nothing
    assert states(manager) == {JTC: "active", POSITION: "inactive", VELOCITY: "inactive"}


def test_a_switch_reports_as_controller_manager_does(manager):
    """evaluate_switch_result: "Successfully switched controllers!"; a switch that is not
    STRICT also lists what it deactivated and activated (a controller named in both lists
    is restarted)."""
    assert manager.switch([POSITION], [JTC], STRICT) == SwitchResult(
        True, "Successfully switched controllers!")
    assert manager.switch([JTC, UNKNOWN], [POSITION, VELOCITY], BEST_EFFORT) == SwitchResult(
        True, f"Successfully switched controllers!\nDeactivated controllers: [ {POSITION} ]"
              f"\nActivated controllers: [ {JTC} ]")
    assert manager.switch([JTC], [JTC], STRICT).ok
    assert states(manager) == {JTC: "active", POSITION: "inactive", VELOCITY: "inactive"}


@pytest.mark.parametrize("activate_asap", [False, True])
@pytest.mark.parametrize("strictness, expected", [(0, False), (STRICT, False),
                                                  (BEST_EFFORT, True)])
def test_a_switch_request_as_the_service_takes_it(manager, activate_asap, strictness, expected):
    """SwitchController: strictness 0 is controller_manager's default (strict); activate_asap
    changes when, not whether (switch_controller_test_activate_asap): hil switches between
    two cycles either way."""
    request = cdr.encode(cdr.msg(
        cdr.SWITCH_CONTROLLER_REQUEST, activate_controllers=[POSITION, UNKNOWN],
        deactivate_controllers=[JTC], strictness=int(strictness), activate_asap=activate_asap,
        timeout=cdr.duration_msg(0.0)))
    response = cdr.decode(switch_response(manager, request), cdr.SWITCH_CONTROLLER_RESPONSE)
    assert response.ok is expected and states(manager)[POSITION] == (
        "active" if expected else "inactive")


def test_strict_refuses_a_switch_that_leaves_a_joint_without_a_controller(manager):
    """hil's rule (docs/controllers.md): STRICT keeps every joint commanded; BEST_EFFORT lets
    the joints hold their last command."""
    result = manager.switch([], [JTC], Strictness.STRICT)
    assert not result.ok and "joint1" in result.message
    assert manager.switch([], [JTC], Strictness.BEST_EFFORT).ok
    position, velocity = manager.update(0.01, np.full(6, 0.1), np.zeros(6))
    assert position == pytest.approx(np.zeros(6)) and velocity == pytest.approx(np.zeros(6))


def test_deactivating_the_trajectory_controller_aborts_its_goal(manager):
    jtc = manager.trajectory
    jtc.submit("g", TrajectoryGoal(("joint1",), (TrajectoryPoint(1.0, (0.2,)),)))
    assert manager.switch([POSITION], [JTC]).ok
    (done,) = jtc.finished()
    assert done[1].status is GoalStatus.ABORTED and done[1].error_string == DEACTIVATED


def test_a_forward_position_controller_commands_what_it_is_sent_and_refuses_bad_commands(manager):
    assert manager.switch([POSITION], [JTC]).ok
    position, _ = manager.update(0.01, np.zeros(6), np.zeros(6))
    assert position == pytest.approx(np.zeros(6))         # no command yet: held
    forward = manager.forward(POSITION)
    forward.command([0.1, 0.2, 0.0, 0.0, 0.0, 0.0])
    position, velocity = manager.update(0.02, np.zeros(6), np.zeros(6))
    assert position[:2] == pytest.approx([0.1, 0.2]) and velocity == pytest.approx(np.zeros(6))
    for bad, words in (([0.1] * 5, "command size (5) does not match"),
                       ([np.nan] + [0.0] * 5, "joint 'joint1' position nan"),
                       ([9.0] + [0.0] * 5, "joint 'joint1' position 9 is outside")):
        with pytest.raises(ValueError, match=words.replace("(", r"\(").replace(")", r"\)")):
            forward.command(bad)
    assert manager.update(0.03, np.zeros(6), np.zeros(6))[0][:2] == pytest.approx([0.1, 0.2])


def test_a_forward_velocity_controller_moves_the_position_setpoint_by_the_velocity(manager):
    """hil's drives run cyclic synchronous position: a velocity alone is followed by
    advancing the position setpoint each period."""
    assert manager.switch([VELOCITY], [JTC]).ok
    manager.forward(VELOCITY).command([0.5, 0, 0, 0, 0, 0])
    for k in range(10):
        position, velocity = manager.update(0.01 * k, np.zeros(6), np.zeros(6))
    assert position[0] == pytest.approx(10 * 0.5 * PERIOD) and velocity[0] == 0.5


def test_a_velocity_beside_another_controllers_position_is_its_feed_forward_not_integrated(
        manager):
    """A joint whose position one controller claims and whose velocity another does gets
    that position, with the velocity as its feed-forward (it is not advanced by it)."""
    assert manager.switch([POSITION, VELOCITY], [JTC]).ok
    manager.forward(POSITION).command([0.1, 0, 0, 0, 0, 0])
    manager.forward(VELOCITY).command([0.5, 0, 0, 0, 0, 0])
    for k in range(5):
        position, velocity = manager.update(0.01 * k, np.zeros(6), np.zeros(6))
    assert position[0] == pytest.approx(0.1) and velocity[0] == 0.5


def test_after_a_fault_a_streaming_controller_forgets_its_command(manager):
    assert manager.switch([VELOCITY], [JTC]).ok
    manager.forward(VELOCITY).command([0.5, 0, 0, 0, 0, 0])
    manager.update(0.0, np.zeros(6), np.zeros(6))
    manager.hold(np.full(6, 0.2))
    position, velocity = manager.update(0.01, np.zeros(6), np.zeros(6))
    assert position == pytest.approx(np.full(6, 0.2)) and velocity == pytest.approx(np.zeros(6))


def test_the_ur_files_constraints_take_effect_on_the_ur3_in_lock_step():
    """Its JTC takes only full goals; a goal ends within the file's goal tolerance (0.1)
    and succeeds; goal_time 0 waits; a goal's own goal_time_tolerance aborts it."""
    config = load_bus_config(UR_BENCH)
    with running_stack(config, LOCK_STEP, interface="virtual") as stack:
        client = TrajectoryActionClient(stack.zenoh, config.robot.name)
        joints = tuple(f"joint{i}" for i in range(1, 7))
        partial = TrajectoryGoal(("joint1",), (TrajectoryPoint(1.0, (0.2,)),))
        with pytest.raises(GoalRejected, match="allow_partial_joints_goal is false"):
            client.send_goal(partial)
        move = TrajectoryGoal(joints, (TrajectoryPoint(1.0, (0.2, -0.1, 0, 0, 0, 0)),))
        assert client.wait_result(client.send_goal(move), 60).status is GoalStatus.SUCCEEDED
        unreachable = TrajectoryGoal(
            joints, (TrajectoryPoint(1.0, (0.3, -0.1, 0, 0, 0, 0)),),
            goal_tolerance=(JointTolerance("joint1", 1e-7),), goal_time_tolerance=0.05)
        result = client.wait_result(client.send_goal(unreachable), 60)
        assert result.status is GoalStatus.ABORTED and result.error_string.startswith(
            "Aborted due to goal_time_tolerance exceeding by")
        client.close()


def test_a_streaming_client_switches_to_forward_position_and_back():
    """The issue's scenario: JTC -> forward position controller (strict), setpoints at
    100 Hz for 2 s, back to the JTC, a trajectory goal succeeds; a switch leaving the joints
    without a controller is refused in STRICT."""
    config = load_bus_config(HERE / "fixtures" / "ur3_virtual.yaml")
    with running_stack(config, LOCK_STEP, interface="virtual") as stack:
        manager = ControllerManagerClient(stack.zenoh, config.robot.name)
        action = TrajectoryActionClient(stack.zenoh, config.robot.name)
        ok, message = manager.switch([], [JTC])
        assert not ok and "without a controller" in message
        ok, message = manager.switch([POSITION], [JTC])
        assert ok, message
        for k in range(200):
            manager.command(POSITION, [0.1 * k / 199, 0, 0, 0, 0, 0])
            time.sleep(0.01)
        manager.command(POSITION, [0.1, 0, 0, 0, 0, 0], wait=True)
        states = {s.name: s.state for s in manager.list()}
        assert states[POSITION] == "active" and states[JTC] == "inactive"
        deadline = time.monotonic() + 30
        while abs(stack.sim.plant.joint_positions()[0] - 0.1) > 0.005:
            assert time.monotonic() < deadline, "the joint did not follow the stream"
            time.sleep(0.05)
        with pytest.raises(ValueError, match="is not active"):
            manager.command(VELOCITY, [0.0] * 6, wait=True)
        assert manager.switch([JTC], [POSITION]) == (True, "Successfully switched controllers!")
        goal = TrajectoryGoal(("joint1",), (TrajectoryPoint(1.0, (-0.1,)),))
        assert action.wait_result(action.send_goal(goal), 60).status is GoalStatus.SUCCEEDED
        action.close()



@pytest.fixture
def controller_later(processes):
    """A loopback endpoint where `hil control ur3 --fake` starts listening a second from now
    (a client asks before the controller is there); the controller is stopped afterwards."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"

    def start() -> None:
        processes.append(subprocess.Popen(
            [sys.executable, "-m", "hil", "control", "ur3", "--fake", "--listen", endpoint],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True))

    timer = threading.Timer(1.0, start)
    timer.start()
    yield endpoint
    timer.join()
    for process in processes:
        process.send_signal(signal.SIGINT)
        process.wait(30)


def test_hil_controllers_waits_for_a_controller_that_comes_after_it(controller_later,
                                                                     processes):
    """Asked before its session knew of the controller's queries, `hil controllers` met no
    one at once and said so (after a `hil send`, one call in two). It waits for the
    controller, as `hil send` and `hil reset` do, up to its --timeout."""
    listing = subprocess.Popen([sys.executable, "-m", "hil", "controllers", "ur3", "--connect",
                                controller_later, "--timeout", "60s"], stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    processes.append(listing)
    out, err = listing.communicate(timeout=90)
    assert listing.returncode == 0, err
    assert [line.split()[0] for line in out.splitlines()] == [JTC, POSITION, VELOCITY]


def test_a_controller_manager_client_on_a_new_session_waits_for_the_controller(
        controller_later):
    """docs/controllers.md's client, made on a session just opened: its first query asks
    again until a controller answers, within its timeout."""
    settings = ZenohSettings(connect=(controller_later,))
    try:
        manager = ControllerManagerClient(session(settings), "ur3", timeout=60)
        assert [state.name for state in manager.list()] == [JTC, POSITION, VELOCITY]
    finally:
        close(settings)
