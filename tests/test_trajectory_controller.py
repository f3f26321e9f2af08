"""Joint trajectory controller semantics, against an ideal or lagging follower."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hil.controllers import (
    INVALID_GOAL, INVALID_JOINTS, PATH_TOLERANCE_VIOLATED,
    GoalRejected, GoalStatus, JointTolerance, JointTrajectoryController, JtcParameters,
    TrajectoryGoal, TrajectoryPoint, TrajectoryPoints,
)
from hil.controllers.config import DEFAULT_GOAL_TOLERANCE, hil_controllers
from hil.controllers import planning
from hil.controllers import trajectory as trajectory_module
from hil.controllers.goal import MAX_POINTS
from trajectory_follower import Follower, goal

def hil_parameters(robot):
    """hil's own controller set's JTC parameters (partial goals, 0.02 goal tolerance, 1 s)."""
    return hil_controllers(tuple(j.name for j in robot.driven_joints),
                           DEFAULT_GOAL_TOLERANCE).trajectory


@pytest.fixture
def ur3_jtc(ur3):
    return JointTrajectoryController(ur3, hil_parameters(ur3))


def test_multi_point_goal_succeeds_at_the_last_point(ur3_jtc):
    follower = Follower(ur3_jtc)
    follower.run(0.01)
    ur3_jtc.submit("g1", goal(["joint1", "joint2"], (1.0, [0.3, -0.2]), (2.0, [0.5, 0.1])))
    results = follower.run(2.5)
    assert results == [("g1", results[0][1])] and results[0][1].status is GoalStatus.SUCCEEDED
    assert follower.q[:2] == pytest.approx([0.5, 0.1], abs=1e-9)
    assert follower.q[2:] == pytest.approx(0.0)                 # partial goal: others hold


def test_linear_interpolation_for_positions_only(ur3_jtc):
    follower = Follower(ur3_jtc)
    follower.run(0.01)
    ur3_jtc.submit("g", goal(["joint1"], (1.0, [0.4])))
    follower.run(0.5)
    assert follower.q[0] == pytest.approx(0.2, abs=0.005)


def test_cubic_when_velocities_are_given_passes_through_with_that_velocity(ur3_jtc):
    follower = Follower(ur3_jtc)
    follower.run(0.01)
    ur3_jtc.submit("g", goal(["joint1"], (1.0, [0.3], [0.5]), (2.0, [0.6], [0.0])))
    follower.run(1.0)
    state = ur3_jtc.state()
    assert state.desired_positions[0] == pytest.approx(0.3, abs=2e-3)
    assert state.desired_velocities[0] == pytest.approx(0.5, abs=5e-3)


def test_quintic_when_accelerations_are_given(ur3_jtc):
    follower = Follower(ur3_jtc)
    follower.run(0.01)
    ur3_jtc.submit("g", goal(["joint1"], (1.0, [0.5], [0.0], [0.0])))
    follower.run(0.5)                                        # symmetric: half way at t/2
    assert ur3_jtc.state().desired_positions[0] == pytest.approx(0.25, abs=3e-3)
    assert follower.run(0.6)[0][1].status is GoalStatus.SUCCEEDED


def test_path_tolerance_violation_aborts_naming_the_joint_in_the_log(ur3_jtc, caplog):
    follower = Follower(ur3_jtc, lag=0.3)
    follower.run(0.01)
    ur3_jtc.submit("g", goal(["joint1", "joint3"], (1.0, [0.0, 0.8]),
                             path_tolerance=(JointTolerance("joint3", position=0.05),)))
    (result,) = follower.run(1.0)
    assert result[1].status is GoalStatus.ABORTED
    assert result[1].error_code == PATH_TOLERANCE_VIOLATED
    assert "joint 'joint3' position error" in caplog.text


@pytest.mark.parametrize("bad, code, words", [
    (goal(["joint9"], (1.0, [0.1])), INVALID_JOINTS, "unknown joint 'joint9'"),
    (goal(["joint1", "joint1"], (1.0, [0.1, 0.1])), INVALID_JOINTS, "named twice"),
    (goal(["joint1"], (1.0, [4.0])), INVALID_GOAL, "point 0 joint 'joint1' position 4 is outside"),
    (goal(["joint1"], (1.0, [0.1]), (1.0, [0.2])), INVALID_GOAL,
     "point 1 time_from_start 1.0 is not after"),
    (goal(["joint1"], (1.0, [math.nan])), INVALID_GOAL, "point 0 joint 'joint1' position is nan"),
    (goal(["joint1"], (1.0, [0.1], [math.inf])), INVALID_GOAL, "velocity is inf"),
    (goal(["joint1"], (1.0, [0.1], [2.0])), INVALID_GOAL, "velocity 2 exceeds its limit 1"),
    (goal(["joint1"], (1.0, [0.1]), (1.1, [0.5])), INVALID_GOAL,
     "point 1 joint 'joint1' needs 4 on average"),
    (goal(["joint1"], (0.1, [0.5])), INVALID_GOAL, "point 0 joint 'joint1' needs 5 on average"),
    (goal(["joint1"], (1.0, [0.1, 0.2])), INVALID_GOAL, "point 0 has 2 positions for 1 joints"),
    (goal(["joint1"]), INVALID_GOAL, "no points"),
    (goal(["joint1"], (1.0, [0.1], (), [0.0])), INVALID_GOAL,
     "point 0 gives accelerations without velocities"),
    (TrajectoryGoal(("joint1",), TrajectoryPoints(np.array([1.0]), np.array([[0.1]]),
                                                  accelerations=np.array([[0.0]]))),
     INVALID_GOAL, "the goal gives accelerations without velocities"),
])
def test_bad_goals_are_rejected_before_any_motion(ur3_jtc, bad, code, words):
    follower = Follower(ur3_jtc)
    follower.run(0.01)
    with pytest.raises(GoalRejected) as caught:
        ur3_jtc.submit("bad", bad)
    assert caught.value.error_code == code and words in str(caught.value)
    follower.run(0.2)
    assert follower.q == pytest.approx(0.0) and ur3_jtc.active_goal is None


def test_mimic_joint_cannot_be_commanded(pigot):
    jtc = JointTrajectoryController(pigot)
    Follower(jtc).run(0.01)
    assert "finger_pri_2" not in jtc.joint_names
    with pytest.raises(GoalRejected, match="mimics 'finger_pri_1'"):
        jtc.submit("g", goal(["finger_pri_2"], (1.0, [0.01])))


def test_continuous_joint_takes_the_short_way_round(tmp_path, package_path):
    from hil.description import load_description
    urdf = tmp_path / "wheel.urdf"
    inertial = ('<inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" '
                'iyz="0" izz="0.01"/></inertial>')
    urdf.write_text(f'<robot name="w"><link name="a">{inertial}</link><link name="b">{inertial}'
                    '</link><joint name="spin" type="continuous"><parent link="a"/><child '
                    'link="b"/><limit effort="1" velocity="10"/></joint><transmission name="t">'
                    '<type>transmission_interface/SimpleTransmission</type><joint name="spin"/>'
                    '<actuator name="m"><mechanicalReduction>10</mechanicalReduction></actuator>'
                    '</transmission></robot>')
    jtc = JointTrajectoryController(load_description(urdf, package_path))
    follower = Follower(jtc)
    follower.q[:] = 3.0
    follower.run(0.01)
    jtc.submit("g", goal(["spin"], (1.0, [-3.0])))          # -3 == 3.283: +0.28 rad, not -6
    follower.run(0.5)
    assert 3.0 < follower.q[0] < 3.3
    assert follower.run(1.0)[0][1].status is GoalStatus.SUCCEEDED


def test_goals_wait_for_the_first_joint_state(ur3_jtc):
    with pytest.raises(GoalRejected, match="no joint state yet"):
        ur3_jtc.submit("early", goal(["joint1"], (1.0, [0.1])))


def _long_goal(points: int, arrays: bool):
    """A 6-joint goal of ``points`` points, 2 ms apart, a slow sine wave from 0."""
    times = 0.5 + 0.002 * np.arange(points)
    positions = 0.2 * np.sin(np.outer(np.arange(points) * 5e-4, np.ones(6)) + np.arange(6)) - \
        0.2 * np.sin(np.arange(6))
    names = tuple(f"joint{j}" for j in range(1, 7))
    if arrays:
        return TrajectoryGoal(names, TrajectoryPoints(times, positions))
    return TrajectoryGoal(names, tuple(TrajectoryPoint(t, tuple(p))
                                       for t, p in zip(times.tolist(), positions.tolist())))


@pytest.mark.parametrize("arrays", [False, True], ids=["points", "arrays"])
def test_a_10000_point_goal_is_followed_to_its_last_point(ur3_jtc, arrays):
    follower = Follower(ur3_jtc)
    follower.run(0.01)
    big = _long_goal(10_000, arrays)
    ur3_jtc.submit("long", big)
    desired = []
    for _ in range(5):                                    # samples along the way
        follower.run(4.0)
        desired.append(follower.q.copy())
    results = follower.run(1.0)
    assert results[0][1].status is GoalStatus.SUCCEEDED
    last = np.array(big.points[-1].positions)
    assert follower.q == pytest.approx(last, abs=1e-9)
    # on the way it follows the points (linear between them): at t = 0.5 + 0.002 k + 0.01
    k = round((4.0 + 0.01 - 0.5) / 0.002)
    assert desired[0] == pytest.approx(np.array(big.points[k].positions), abs=1e-3)


def test_a_goal_is_checked_and_planned_without_the_controllers_lock(ur3_jtc, monkeypatch):
    """The control cycle must not wait for a large goal's checks and planning (on one goal
    of 10,000 points that held the real-time loop for 130 ms)."""
    follower = Follower(ur3_jtc)
    follower.run(0.01)
    held_while_planning = []
    plan = trajectory_module.plan_goal

    def watched(limits, parameters, goal):
        held_while_planning.append(ur3_jtc._lock.locked())
        return plan(limits, parameters, goal)

    monkeypatch.setattr(trajectory_module, "plan_goal", watched)
    ur3_jtc.submit("long", _long_goal(10_000, arrays=False))
    assert held_while_planning == [False]
    assert ur3_jtc.active_goal == "long"


def test_a_goal_over_the_point_limit_is_refused_naming_the_limit(ur3_jtc):
    Follower(ur3_jtc).run(0.01)
    with pytest.raises(GoalRejected, match=f"at most {MAX_POINTS}"):
        ur3_jtc.submit("huge", _long_goal(MAX_POINTS + 1, arrays=True))


def test_a_decoded_goal_keeps_its_points_as_arrays():
    from hil.messaging import cdr
    sent = _long_goal(50, arrays=False)
    decoded = cdr.goal_from_msg(cdr.decode(cdr.encode(cdr.goal_msg(sent)),
                                           "control_msgs/action/FollowJointTrajectory_Goal"), None)
    assert isinstance(decoded.points, TrajectoryPoints)
    assert [p.positions for p in decoded.points] == [p.positions for p in sent.points]
    assert [p.time_from_start for p in decoded.points] == pytest.approx(   # whole nanoseconds
        [p.time_from_start for p in sent.points], abs=1e-9)


def _integrating(robot, **parameters) -> JointTrajectoryController:
    """A JTC over every driven joint with allow_integration_in_goal_trajectories."""
    return JointTrajectoryController(robot, JtcParameters(
        joints=tuple(j.name for j in robot.driven_joints),
        allow_integration_in_goal_trajectories=True, **parameters))


def _integrations(jtc, monkeypatch) -> list[bool]:
    """Whether the controller's lock was held at each integration of a goal's points."""
    held = []
    integrate = planning.integrated

    def watched(*args, **kwargs):
        held.append(jtc._lock.locked())
        return integrate(*args, **kwargs)

    monkeypatch.setattr(planning, "integrated", watched)
    return held


def test_an_integrated_goal_from_an_unchanged_state_is_planned_without_the_lock(ur3, monkeypatch):
    """allow_integration_in_goal_trajectories: the points are integrated from the state
    when the goal arrives, without the controller's lock; at rest, holding the last
    command (interpolate_from_desired_state), the state it starts from is that one, and the
    control cycle does not wait for the integration again."""
    jtc = _integrating(ur3, interpolate_from_desired_state=True)
    follower = Follower(jtc)
    follower.run(0.01)
    held_while_integrating = _integrations(jtc, monkeypatch)
    times = np.arange(1, 10_001) * 0.002
    velocities = np.zeros((len(times), 6))
    velocities[:-1, 0] = 0.05
    jtc.submit("long", TrajectoryGoal(jtc.joint_names, tuple(
        TrajectoryPoint(t, (), tuple(v)) for t, v in zip(times.tolist(), velocities.tolist()))))
    assert held_while_integrating == [False] and jtc.active_goal == "long"
    follower.run(20.02)
    assert follower.q[0] == pytest.approx(0.05 * (20.0 - 0.002), abs=1e-9)


def test_an_integrated_goal_is_integrated_again_from_the_state_it_starts_from(ur3, monkeypatch):
    """Where a cycle changes the state while the goal is planned, its points are integrated
    again, under the lock, from the state the goal starts from (the JTC's point before the
    trajectory is the state at its first sample): from 0.1, v = 0.1 at 1 s passes 0.15."""
    jtc = _integrating(ur3, allow_nonzero_velocity_at_trajectory_end=True)
    follower = Follower(jtc)
    follower.run(0.01)
    held_while_integrating = _integrations(jtc, monkeypatch)
    plan = trajectory_module.plan_goal

    def moved_while_planning(*args):
        follower.q[0] = 0.1                  # measured at the next cycle
        follower.run(0.002)
        return plan(*args)

    monkeypatch.setattr(trajectory_module, "plan_goal", moved_while_planning)
    jtc.submit("g", goal(jtc.joint_names, (1.0, [], [0.1, 0, 0, 0, 0, 0])))
    assert held_while_integrating == [False, True]
    follower.run(1.0)
    assert jtc.state().desired_positions[0] == pytest.approx(0.1 + 0.1 / 2)
