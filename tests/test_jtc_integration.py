"""allow_integration_in_goal_trajectories as ros2_controllers' JTC (jazzy branch) takes it:
the points validate_trajectory_msg accepts (src/joint_trajectory_controller.cpp;
test/test_trajectory_controller.cpp, missing_positions_message_accepted) and the positions
and velocities it integrates from the point before the trajectory (src/trajectory.cpp,
deduce_from_derivatives and set_point_before_trajectory_msg; test/test_trajectory.cpp,
sample_trajectory_velocity_with_interpolation[_strange_without_vel],
sample_trajectory_acceleration_with_interpolation). Expected numbers are the trapezoid
rule's; the controller runs lock-step against a follower (tests/trajectory_follower.py),
the goal's clock 0 at its arrival."""

from __future__ import annotations

import pytest

from hil.controllers import (
    GoalRejected, GoalStatus, JointTrajectoryController, JtcParameters, TrajectoryGoal,
    TrajectoryPoint,
)
from trajectory_follower import Follower

JOINTS = ("joint1", "joint2", "joint3", "joint4", "joint5", "joint6")
INTEGRATING = {"allow_integration_in_goal_trajectories": True}


def controller(robot, **parameters) -> JointTrajectoryController:
    return JointTrajectoryController(robot, JtcParameters(joints=JOINTS, **parameters))


def point(t, positions=None, velocities=None, accelerations=None) -> TrajectoryPoint:
    """A point giving joint1's values (the others 0) for the fields that are not None."""
    field = lambda value: () if value is None else (value,) + (0.0,) * 5  # noqa: E731
    return TrajectoryPoint(t, field(positions), field(velocities), field(accelerations))


def started(jtc, lag=0.0) -> Follower:
    follower = Follower(jtc, lag)
    follower.run(0.01)
    return follower


def desired(jtc) -> tuple[float, float]:
    """joint1's desired position and velocity."""
    state = jtc.state()
    return state.desired_positions[0], state.desired_velocities[0]


# --- which points validate_trajectory_msg accepts ------------------------------------------

GIVEN = {"positions": 0.01, "velocities": -0.1, "accelerations": 0.1}


@pytest.mark.parametrize("left_out", [(), ("positions",), ("positions", "velocities")],
                         ids=["all three", "no positions", "no positions and velocities"])
def test_with_integration_a_point_may_leave_out_positions_and_velocities(ur3, left_out):
    """missing_positions_message_accepted: "No position data", "No position and velocity
    data" are valid with allow_integration_in_goal_trajectories."""
    jtc = controller(ur3, allow_nonzero_velocity_at_trajectory_end=True, **INTEGRATING)
    given = {k: v for k, v in GIVEN.items() if k not in left_out}
    started(jtc).controller.submit("g", TrajectoryGoal(JOINTS, (point(0.25, **given),)))
    assert jtc.active_goal == "g"


@pytest.mark.parametrize("field", ["positions", "velocities", "accelerations", None])
def test_with_integration_a_point_gives_something_and_a_value_per_joint(ur3, field):
    """missing_positions_message_accepted: "All empty" is refused ("The given trajectory
    has no position, velocity, or acceleration points."), and so is a field of the wrong
    size ("Mismatch between joint_names size ... at point #%zu")."""
    values = {k: (0.0,) * 6 for k in GIVEN}
    if field is None:
        values, words = {k: () for k in GIVEN}, "point 0 gives no positions, velocities or"
    else:
        values[field], words = (0.0, 0.0), f"point 0 has 2 {field} for 6 joints"
    with pytest.raises(GoalRejected, match=words):
        started(controller(ur3, **INTEGRATING)).controller.submit(
            "g", TrajectoryGoal(JOINTS, (TrajectoryPoint(0.5, **values),)))


def test_without_integration_a_point_without_positions_is_refused_naming_the_parameter(ur3):
    """validate_trajectory_msg without allow_integration_in_goal_trajectories: positions
    are not allowed empty (validate_trajectory_point_field(..., "positions", i, false))."""
    with pytest.raises(GoalRejected, match="point 0 has 0 positions for 6 joints; a point "
                                           "without positions needs allow_integration_in"):
        started(controller(ur3)).controller.submit(
            "g", TrajectoryGoal(JOINTS, (point(1.0, velocities=0.0),)))


# --- what it integrates -------------------------------------------------------------------

def test_velocities_alone_are_integrated_from_the_state_by_the_trapezoid_rule(ur3):
    """sample_trajectory_velocity_with_interpolation_strange_without_vel: from rest at 0
    (a state without velocity: 0), v = 0.1, 0.2, 0.1 at 1, 2, 3 s gives positions
    0.05, 0.05 + 0.15 = 0.2, 0.2 + 0.15 = 0.35; half way to the first, the cubic's
    0.0125 at 0.05 rad/s."""
    jtc = controller(ur3, state_interfaces=("position",),
                     allow_nonzero_velocity_at_trajectory_end=True, **INTEGRATING)
    follower = started(jtc)
    jtc.submit("g", TrajectoryGoal(JOINTS, (point(1.0, velocities=0.1),
                                            point(2.0, velocities=0.2),
                                            point(3.0, velocities=0.1))))
    # a goal submitted after the follower's last update: each run ends on the goal's clock
    for seconds, position, velocity in [(0.5, 0.0125, 0.05), (0.5, 0.05, 0.1), (1.0, 0.2, 0.2)]:
        follower.run(seconds)
        assert desired(jtc) == pytest.approx((position, velocity))
    (done,) = follower.run(1.02)
    assert done[1].status is GoalStatus.SUCCEEDED and follower.q[0] == pytest.approx(0.35)


def test_accelerations_alone_are_integrated_into_velocities_then_positions(ur3):
    """sample_trajectory_acceleration_with_interpolation: from rest, a = 0.1, 0.2, 0.1 at
    1, 2, 3 s gives velocities 0.05, 0.2, 0.35 and positions 0.025, 0.15, 0.425 (the last
    point's integrated velocity is not the goal's: validate_trajectory_msg does not check
    it)."""
    jtc = controller(ur3, **INTEGRATING)
    follower = started(jtc)
    jtc.submit("g", TrajectoryGoal(JOINTS, (point(1.0, accelerations=0.1),
                                            point(2.0, accelerations=0.2),
                                            point(3.0, accelerations=0.1))))
    for position, velocity in [(0.025, 0.05), (0.15, 0.2)]:
        follower.run(1.0)
        assert desired(jtc) == pytest.approx((position, velocity))
    (done,) = follower.run(1.02)
    assert done[1].status is GoalStatus.SUCCEEDED and follower.q[0] == pytest.approx(0.425)


def test_a_point_without_positions_continues_from_the_point_before(ur3):
    """deduce_from_derivatives(point, next_point): a point's positions from the point before
    it, whose missing velocities are 0 (resized): 0.1 at 1 s, then v = 0.1 at 2 s and 0 at
    3 s give 0.1 + (0 + 0.1) / 2 = 0.15 and 0.15 + (0.1 + 0) / 2 = 0.2."""
    jtc = controller(ur3, **INTEGRATING)
    follower = started(jtc)
    jtc.submit("g", TrajectoryGoal(JOINTS, (point(1.0, positions=0.1),
                                            point(2.0, velocities=0.1),
                                            point(3.0, velocities=0.0))))
    follower.run(2.0)
    assert desired(jtc) == pytest.approx((0.15, 0.1))
    (done,) = follower.run(1.02)
    assert done[1].status is GoalStatus.SUCCEEDED and follower.q[0] == pytest.approx(0.2)


def test_a_joint_moving_at_v_for_t_seconds_more_ends_v_times_t_further(ur3):
    """The first segment integrates from the point before the trajectory, here the last
    command (interpolate_from_desired_state) of a goal moving joint1 at 0.1 rad/s through
    0.15: v = 0.1 at 1 s and 2 s then passes 0.15 + 0.1 * 1 and ends at 0.15 + 0.1 * 2."""
    jtc = controller(ur3, interpolate_from_desired_state=True,
                     allow_nonzero_velocity_at_trajectory_end=True, **INTEGRATING)
    follower = started(jtc)
    jtc.submit("first", TrajectoryGoal(JOINTS, (point(1.0, 0.1, 0.1), point(2.0, 0.2, 0.1))))
    follower.run(1.5)
    assert desired(jtc) == pytest.approx((0.15, 0.1))
    jtc.submit("g", TrajectoryGoal(JOINTS, (point(1.0, velocities=0.1),
                                            point(2.0, velocities=0.1))))
    follower.run(1.0)
    assert desired(jtc) == pytest.approx((0.25, 0.1))
    follower.run(1.0)
    assert desired(jtc)[0] == pytest.approx(0.35)


def test_a_first_point_without_positions_due_at_once_is_refused(ur3):
    """hil's choice: jazzy integrates point 0 only while sampling before it; due at once,
    it reads an empty positions vector (trajectory.cpp, the segment after point 0)."""
    with pytest.raises(GoalRejected, match="point 0 gives no positions and is due at once"):
        started(controller(ur3, **INTEGRATING)).controller.submit(
            "g", TrajectoryGoal(JOINTS, (point(0.0, velocities=0.0),
                                         point(1.0, velocities=0.0))))


# --- the point before the trajectory --------------------------------------------------------

def test_the_state_before_has_no_velocity_without_a_velocity_state_interface(ur3):
    """read_state_from_state_interfaces clears the velocities without a velocity state
    interface; set_point_before_trajectory_msg then starts the first segment at 0 rad/s.
    With one, it starts at the measured velocity."""
    def first_velocity(state_interfaces):
        jtc = controller(ur3, state_interfaces=state_interfaces)
        follower = started(jtc, lag=0.5)
        jtc.submit("g", TrajectoryGoal(JOINTS, (point(1.0, 0.5),)))
        follower.run(0.5)
        measured = jtc.state().actual_velocities[0]
        jtc.submit("h", TrajectoryGoal(JOINTS, (point(2.0, 0.5, 0.0),)))
        follower.run(0.002)
        return measured, desired(jtc)[1]
    measured, moving = first_velocity(("position", "velocity"))
    assert measured > 0.2 and moving == pytest.approx(measured, abs=0.01)
    assert first_velocity(("position",))[1] == pytest.approx(0.0, abs=0.01)
