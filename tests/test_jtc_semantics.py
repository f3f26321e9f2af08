"""The joint trajectory controller as ros2_controllers' JTC behaves where a client sees it.

Each test names its source in ros2_controllers (jazzy branch): the JTC's parameters file
(src/joint_trajectory_controller_parameters.yaml), its code (src/joint_trajectory_controller.cpp,
include/joint_trajectory_controller/tolerances.hpp, src/trajectory.cpp), its tests
(test/test_trajectory_controller.cpp, test/test_trajectory_actions.cpp,
test/test_tolerances.cpp) and docs (doc/userdoc.rst, doc/decelerate_on_cancel.rst).
The controller runs lock-step against a follower (tests/trajectory_follower.py)."""

from __future__ import annotations

import numpy as np
import pytest

from hil.controllers import (
    GOAL_TOLERANCE_VIOLATED, INVALID_GOAL, PATH_TOLERANCE_VIOLATED, SUCCESSFUL, GoalRejected,
    GoalStatus, JointConstraint, JointTolerance, JointTrajectoryController, JtcParameters,
    TrajectoryGoal, TrajectoryPoint,
)
from hil.controllers.goal import DEACTIVATED, PATH_ABORT, PREEMPTED, REACHED
from trajectory_follower import Follower

JOINTS = ("joint1", "joint2", "joint3", "joint4", "joint5", "joint6")


def controller(robot, **parameters) -> JointTrajectoryController:
    return JointTrajectoryController(robot, JtcParameters(joints=JOINTS, **parameters))


def full(*points, **kwargs) -> TrajectoryGoal:
    """A goal over every joint: (time, joint1's position[, joint1's velocity]), the others at 0."""
    def point(t, q, *v):
        return TrajectoryPoint(t, (q, 0, 0, 0, 0, 0), (v[0], 0, 0, 0, 0, 0) if v else ())
    return TrajectoryGoal(JOINTS, tuple(point(*p) for p in points), **kwargs)


def tolerance(position=0.0, velocity=0.0, joint="joint1"):
    return (JointTolerance(joint, position, velocity),)


def started(jtc, lag=0.0) -> Follower:
    follower = Follower(jtc, lag)
    follower.run(0.01)
    return follower


# --- parameters and their defaults ---------------------------------------------------------

def test_parameters_default_as_the_jtc_declares_them():
    """parameters.yaml: allow_partial_joints_goal false, allow_nonzero_velocity_at_trajectory_end
    false, interpolate_from_desired_state false, allow_integration_in_goal_trajectories
    false, action_monitor_rate 20, cmd_timeout 0,
    constraints.stopped_velocity_tolerance 0.01, constraints.goal_time 0, per joint trajectory
    and goal 0, decelerate_on_cancel false."""
    p = JtcParameters(joints=JOINTS)
    assert (p.allow_partial_joints_goal, p.allow_nonzero_velocity_at_trajectory_end,
            p.interpolate_from_desired_state, p.decelerate_on_cancel,
            p.allow_integration_in_goal_trajectories) == (False,) * 5
    assert (p.action_monitor_rate, p.cmd_timeout, p.stopped_velocity_tolerance,
            p.goal_time) == (20.0, 0.0, 0.01, 0.0)
    assert p.constraint("joint1") == JointConstraint(0.0, 0.0, 0.0)


def test_parameters_set_at_run_time_apply_to_the_next_goal(ur3):
    """The JTC's parameter listener updates its default tolerances for goals to come, and
    the parameters validate_trajectory_msg reads (parameters.yaml declares none of these
    read_only)."""
    jtc = controller(ur3)
    jtc.set_parameters({"constraints.goal_time": 0.5, "constraints.joint1.goal": 0.01,
                        "allow_partial_joints_goal": True,
                        "allow_integration_in_goal_trajectories": True})
    assert jtc.parameters.goal_time == 0.5 and jtc.parameters.constraint("joint1").goal == 0.01
    assert jtc.parameters.allow_integration_in_goal_trajectories
    with pytest.raises(ValueError, match="no settable parameter 'joints'"):
        jtc.set_parameters({"joints": ("joint1",)})
    with pytest.raises(ValueError, match="constraints.goal_time must be a finite number"):
        jtc.set_parameters({"constraints.goal_time": -1.0})


# --- validation (validate_trajectory_msg) ------------------------------------------------------

def test_a_partial_goal_is_rejected_unless_allowed(ur3):
    """validate_trajectory_msg: "Joints on incoming trajectory don't match the controller
    joints." without allow_partial_joints_goal (test_trajectory_actions.cpp,
    test_allow_partial_joints_goal); with it, the others hold (fill_partial_goal)."""
    partial = TrajectoryGoal(("joint2",), (TrajectoryPoint(1.0, (0.3,)),))
    with pytest.raises(GoalRejected, match="allow_partial_joints_goal is false"):
        started(controller(ur3)).controller.submit("g", partial)
    jtc = controller(ur3, allow_partial_joints_goal=True)
    follower = started(jtc)
    jtc.submit("g", partial)
    assert follower.run(1.2)[0][1].status is GoalStatus.SUCCEEDED
    assert follower.q[1] == pytest.approx(0.3) and follower.q[0] == pytest.approx(0.0)


def test_a_last_point_still_moving_is_rejected_unless_allowed(ur3):
    """validate_trajectory_msg: "Velocity of last trajectory point of joint %s is not zero"
    (test_trajectory_controller.cpp, test_trajectory_replace/nonzero end velocity)."""
    moving = full((1.0, 0.3, 0.1))
    with pytest.raises(GoalRejected, match="Velocity of last trajectory point of joint joint1"):
        started(controller(ur3)).controller.submit("g", moving)
    jtc = controller(ur3, allow_nonzero_velocity_at_trajectory_end=True)
    started(jtc).controller.submit("g", moving)
    assert jtc.active_goal == "g"


def test_a_last_point_still_moving_is_rejected_where_the_others_give_no_velocities(ur3):
    """validate_trajectory_msg checks trajectory.points.back().velocities as the goal gives
    them, whatever the other points give (hil interpolates such a goal linearly)."""
    moving = full((0.5, 0.1), (1.0, 0.3, 0.1))
    with pytest.raises(GoalRejected, match="Velocity of last trajectory point of joint joint1"):
        started(controller(ur3)).controller.submit("g", moving)


def test_effort_fields_are_rejected_without_an_effort_command_interface(ur3):
    """validate_trajectory_msg: "Trajectories with effort fields are only supported for
    controllers using the 'effort' command interface." (hil's hardware has none)."""
    with pytest.raises(GoalRejected, match="effort fields"):
        started(controller(ur3)).controller.submit(
            "g", TrajectoryGoal(JOINTS, full((1.0, 0.1)).points, has_efforts=True))


def test_a_stamped_goal_that_ends_in_the_past_is_rejected(ur3):
    """validate_trajectory_msg: "Received trajectory with non-zero start time (%f) that ends
    in the past (%f)"."""
    follower = started(controller(ur3))
    follower.run(2.0)
    with pytest.raises(GoalRejected, match="ends in the past"):
        follower.controller.submit("g", full((1.0, 0.1), start_time=follower.t - 1.5))


# --- time: the goal's clock is its stamp ---------------------------------------------------

def test_a_goal_stamped_in_the_past_runs_on_its_stamps_clock(ur3):
    """trajectory.cpp: time 0 of the trajectory is header.stamp; the point before the
    trajectory is the state when it is first sampled. Stamped 0.5 s ago with points at 1 and
    2 s, the goal is done 1.5 s after it arrived."""
    jtc = controller(ur3, constraints={"joint1": JointConstraint(goal=0.01)})
    follower = started(jtc)
    arrival = follower.t
    jtc.submit("g", full((1.0, 0.2), (2.0, 0.4), start_time=arrival - 0.5))
    follower.run(1.45)
    assert jtc.active_goal == "g"
    (done,) = follower.run(0.1)
    assert done[1].status is GoalStatus.SUCCEEDED and follower.t - arrival < 1.6


def test_a_goal_stamped_in_the_future_moves_now_to_reach_its_first_point_on_time(ur3):
    """trajectory.cpp sample(): before the first point, interpolate from the state before the
    trajectory (at the first sample, now) to the first point at stamp + time_from_start."""
    jtc = controller(ur3)
    follower = started(jtc)
    jtc.submit("g", full((0.5, 0.2), start_time=follower.t + 1.0))
    follower.run(0.9)
    assert follower.q[0] == pytest.approx(0.2 * 0.9 / 1.5, abs=2e-3)
    follower.run(0.7)
    assert follower.q[0] == pytest.approx(0.2)


# --- tolerances and how a goal ends --------------------------------------------------------

def test_goal_time_zero_waits_for_the_goal_tolerance_without_a_limit(ur3):
    """parameters.yaml constraints.goal_time: "If set to zero, the controller will wait a
    potentially infinite amount of time" (update(): within_goal_time stays true)."""
    jtc = controller(ur3, constraints={"joint1": JointConstraint(goal=0.002)})
    follower = started(jtc, lag=0.3)
    jtc.submit("g", full((0.5, 0.3)))
    assert follower.run(1.5) == []                  # 1 s past the end, still settling
    (done,) = follower.run(2.0)
    assert (done[1].status, done[1].error_code, done[1].error_string) == (
        GoalStatus.SUCCEEDED, SUCCESSFUL, REACHED)


def test_goal_time_limit_aborts_with_the_jtcs_code_and_string_then_holds_measured(ur3):
    """update(): past goal_time outside the goal tolerance: GOAL_TOLERANCE_VIOLATED, "Aborted
    due to goal_time_tolerance exceeding by %f seconds", then set_hold_position() (the
    measured position)."""
    jtc = controller(ur3, goal_time=0.2, constraints={"joint1": JointConstraint(goal=0.001)})
    follower = started(jtc, lag=0.3)
    jtc.submit("g", full((0.5, 0.3)))
    (done,) = follower.run(1.0)
    result = done[1]
    assert (result.status, result.error_code) == (GoalStatus.ABORTED, GOAL_TOLERANCE_VIOLATED)
    assert result.error_string.startswith("Aborted due to goal_time_tolerance exceeding by 0.2")
    held = jtc.state().desired_positions[0]
    assert held < 0.3 - 0.001                        # where it was, not the goal
    follower.run(1.0)
    assert follower.q[0] == pytest.approx(held, abs=1e-6)


def test_a_goals_goal_time_tolerance_minus_one_erases_the_limit(ur3):
    """tolerances.hpp resolve_tolerance_source: -1 erases (test_tolerances.cpp,
    test_get_segment_tolerances_erase)."""
    jtc = controller(ur3, goal_time=0.2, constraints={"joint1": JointConstraint(goal=0.002)})
    follower = started(jtc, lag=0.3)
    jtc.submit("g", full((0.5, 0.3), goal_time_tolerance=-1.0))
    assert follower.run(1.5) == []
    assert follower.run(2.0)[0][1].status is GoalStatus.SUCCEEDED


def test_a_goals_own_tolerances_override_the_defaults_and_zero_keeps_them(ur3):
    """get_segment_tolerances(goal): > 0 replaces the default, 0 keeps it."""
    jtc = controller(ur3, goal_time=0.1, constraints={"joint1": JointConstraint(goal=0.001)})
    follower = started(jtc, lag=0.3)
    jtc.submit("g", full((0.5, 0.3), goal_tolerance=tolerance(position=0.2)))
    assert follower.run(0.6)[0][1].status is GoalStatus.SUCCEEDED
    jtc.submit("h", full((0.5, 0.0), goal_tolerance=tolerance(position=0.0)))
    assert follower.run(1.0)[0][1].error_code == GOAL_TOLERANCE_VIOLATED


@pytest.mark.parametrize("bad", [
    tolerance(position=0.2) + tolerance(position=0.2, joint="elbow"),
    tolerance(position=-123.0),
    (),
], ids=["unknown joint", "illegal value", "goal_time_tolerance -3"])
def test_invalid_goal_tolerances_fall_back_to_the_defaults(ur3, bad, caplog):
    """get_segment_tolerances(goal): a joint it does not have or an illegal value (negative,
    not -1) is logged and the goal runs with the default tolerances (not rejected)."""
    jtc = controller(ur3, goal_time=0.1, constraints={"joint1": JointConstraint(goal=0.001)})
    follower = started(jtc, lag=0.3)
    jtc.submit("g", full((0.5, 0.3), goal_tolerance=bad,
                         goal_time_tolerance=0.0 if bad else -3.0))
    assert "Using default tolerances" in caplog.text
    (done,) = follower.run(1.0)                      # with the goal's 0.2: success at 0.5 s
    assert done[1].error_code == GOAL_TOLERANCE_VIOLATED


def test_a_broken_path_tolerance_aborts_with_the_jtcs_string_and_holds_measured(ur3):
    """update(): PATH_TOLERANCE_VIOLATED "Aborted due to path tolerance violation", then
    set_hold_position()."""
    jtc = controller(ur3, constraints={"joint1": JointConstraint(trajectory=0.05)})
    follower = started(jtc, lag=0.3)
    jtc.submit("g", full((1.0, 0.8)))
    (done,) = follower.run(1.0)
    assert (done[1].status, done[1].error_code, done[1].error_string) == (
        GoalStatus.ABORTED, PATH_TOLERANCE_VIOLATED, PATH_ABORT)
    held = jtc.state().desired_positions[0]
    follower.run(1.0)
    assert follower.q[0] == pytest.approx(held, abs=1e-6)


def test_a_path_and_a_goal_tolerance_set_in_one_change_both_take_effect(ur3):
    """rclcpp's set_parameters_atomically hands the JTC's parameter listener every parameter
    of the request at once; each one it names is set (generate_parameter_library's
    update(): one assignment per parameter). Setting constraints.joint1.trajectory and
    .goal together keeps both: the path tolerance still aborts the lagging move."""
    jtc = controller(ur3)
    jtc.set_parameters({"constraints.joint1.trajectory": 0.05, "constraints.joint1.goal": 0.1})
    assert jtc.parameters.constraint("joint1") == JointConstraint(trajectory=0.05, goal=0.1)
    follower = started(jtc, lag=0.3)
    jtc.submit("g", full((1.0, 0.8)))
    (done,) = follower.run(1.0)
    assert (done[1].status, done[1].error_code) == (GoalStatus.ABORTED, PATH_TOLERANCE_VIOLATED)


def test_a_path_tolerance_of_minus_one_erases_the_default(ur3):
    """resolve_tolerance_source: -1 erases a default path tolerance."""
    jtc = controller(ur3, constraints={"joint1": JointConstraint(trajectory=0.05)})
    follower = started(jtc, lag=0.3)
    jtc.submit("g", full((1.0, 0.8), path_tolerance=tolerance(position=-1.0)))
    assert follower.run(3.0)[0][1].status is GoalStatus.SUCCEEDED


def test_stopped_velocity_tolerance_holds_a_goal_until_the_joint_is_at_rest(ur3):
    """get_segment_tolerances(params): the goal's velocity tolerance is
    stopped_velocity_tolerance, checked on the velocity error where velocity is commanded
    and measured (compute_error_for_joint); with a position-only command interface the
    velocity error is not computed."""
    def finish_time(command_interfaces):
        jtc = controller(ur3, command_interfaces=command_interfaces,
                         state_interfaces=("position", "velocity"),
                         stopped_velocity_tolerance=0.01)
        follower = started(jtc, lag=0.3)
        jtc.submit("g", full((0.5, 0.3)))
        while not follower.run(0.01):
            pass
        return follower.t
    assert finish_time(("position",)) < 0.53 < finish_time(("position", "velocity"))


def test_success_uses_the_jtcs_string(ur3):
    """update(): SUCCESSFUL, "Goal successfully reached!"."""
    jtc = controller(ur3)
    follower = started(jtc)
    jtc.submit("g", full((0.5, 0.1)))
    (done,) = follower.run(0.6)
    assert (done[1].status, done[1].error_code, done[1].error_string) == (
        GoalStatus.SUCCEEDED, SUCCESSFUL, REACHED)


def test_a_new_goal_preempts_with_the_jtcs_code_and_string(ur3):
    """preempt_active_goal(): INVALID_GOAL, "Current goal preempted by new incoming action."."""
    jtc = controller(ur3)
    follower = started(jtc)
    jtc.submit("first", full((2.0, 0.5)))
    follower.run(0.5)
    jtc.submit("second", full((1.0, -0.2)))
    (preempted,) = jtc.finished()
    assert preempted[0] == "first" and (preempted[1].status, preempted[1].error_code,
                                        preempted[1].error_string) == (
        GoalStatus.ABORTED, INVALID_GOAL, PREEMPTED)
    assert follower.run(1.5)[0][1].status is GoalStatus.SUCCEEDED


def test_cancel_holds_the_measured_position_with_an_empty_result(ur3):
    """goal_cancelled_callback(): setCanceled with a default Result (code 0, ""), then
    set_hold_position()."""
    jtc = controller(ur3)
    follower = started(jtc, lag=0.1)
    jtc.submit("g", full((2.0, 1.0)))
    follower.run(1.0)
    assert jtc.cancel("g")
    state = jtc.state()
    assert state.desired_positions[0] == state.actual_positions[0] > 0.1
    (done,) = jtc.finished()
    assert (done[1].status, done[1].error_code, done[1].error_string) == (
        GoalStatus.CANCELED, 0, "")
    assert not jtc.cancel("g")


def test_decelerate_on_cancel_ramps_each_joint_to_rest(ur3):
    """doc/decelerate_on_cancel.rst (optional feature): from the measured velocity at each
    joint's max_deceleration_on_cancel, stopping at p0 + v0^2 / (2 a)."""
    jtc = controller(ur3, decelerate_on_cancel=True, constraints={
        j: JointConstraint(max_deceleration_on_cancel=2.0) for j in JOINTS})
    follower = started(jtc)
    jtc.submit("g", full((0.1, 0.0), (2.0, 0.95), (2.1, 0.95)))
    follower.run(1.0)
    state = jtc.state()
    p0, v0 = state.actual_positions[0], state.actual_velocities[0]
    jtc.cancel("g")
    follower.run(1.0)
    assert v0 == pytest.approx(0.5, abs=0.01)
    assert follower.q[0] == pytest.approx(p0 + v0 ** 2 / 4.0, abs=1e-3)


def test_cmd_timeout_holds_after_the_last_point_and_the_goal_reports_reached(ur3):
    """update(): past the last point by cmd_timeout (> goal_time): "Aborted due to command
    timeout", hold; holding, no tolerance is checked, and the goal is reported reached."""
    jtc = controller(ur3, cmd_timeout=0.3, constraints={"joint1": JointConstraint(goal=0.0001)})
    follower = started(jtc, lag=0.3)
    jtc.submit("g", full((0.5, 0.3)))
    assert follower.run(0.75) == []
    (done,) = follower.run(0.1)
    assert done[1].status is GoalStatus.SUCCEEDED
    held = jtc.state().desired_positions[0]
    assert held < 0.3 - 0.0001


def test_the_first_segment_starts_from_the_measured_state_unless_from_desired(ur3):
    """set_point_before_trajectory_msg: the measured state (state_current_), or the last
    command with interpolate_from_desired_state."""
    for from_desired in (False, True):
        jtc = controller(ur3, interpolate_from_desired_state=from_desired)
        follower = started(jtc, lag=0.5)
        jtc.submit("g", full((1.0, 0.5)))
        follower.run(0.5)
        jtc.submit("h", full((2.0, 0.5)))
        follower.run(0.002)
        expected = jtc.state().desired_positions[0]
        assert (abs(expected - follower.q[0]) < 0.01) is not from_desired


def test_deactivating_aborts_the_goal_and_an_inactive_controller_takes_none(ur3):
    """on_deactivate(): INVALID_GOAL "Current goal cancelled during deactivate transition.";
    goal_received_callback(): "Can't accept new action goals. Controller is not running."."""
    jtc = controller(ur3)
    started(jtc).controller.submit("g", full((1.0, 0.1)))
    jtc.deactivate()
    (done,) = jtc.finished()
    assert (done[1].status, done[1].error_code, done[1].error_string) == (
        GoalStatus.ABORTED, INVALID_GOAL, DEACTIVATED)
    with pytest.raises(GoalRejected, match="Controller is not running"):
        jtc.submit("h", full((1.0, 0.1)))
    jtc.activate(0.0, np.zeros(6))
    jtc.submit("h", full((1.0, 0.1)))


def test_hils_stricter_first_point_check_and_the_parameter_that_drops_it(ur3):
    """hil's own (reject_unreachable_first_point): a first point the joints cannot reach in
    time at their velocity limits is refused; False gives the JTC's behaviour (it commands
    the jump)."""
    jtc = controller(ur3)
    with pytest.raises(GoalRejected, match="reject_unreachable_first_point"):
        started(jtc).controller.submit("g", full((0.0, 0.5), (1.0, 0.6)))
    loose = controller(ur3, reject_unreachable_first_point=False)
    follower = started(loose)
    loose.submit("g", full((0.0, 0.5), (1.0, 0.6)))
    follower.run(0.004)
    assert follower.q[0] == pytest.approx(0.5, abs=1e-3)
