"""A wheeled base on a floor (``base: floating``, docs/configuration.md "Floating base"):
the inertia each wheel motor sees rolling the robot is finite, drives are tuned on it, and
a lock-step bench of tests/fixtures/wheeled_arm.yaml enables its wheel drives and moves its
arm. An inertia hil cannot tune on is refused at start, naming the drive."""

from __future__ import annotations

import math

import can
import numpy as np
import pytest

from hil.bus_config import load_bus_config
from hil.controllers import TrajectoryGoal, TrajectoryPoint
from hil.errors import HilError
from hil.messaging.zenoh_api import TrajectoryActionClient
from hil.plant import Plant
from hil.realtime import LOCK_STEP
from hil.simulator import Simulator, bench_plant, drive_parameters
from hil.stack import running_stack
from conftest import TESTS

WHEELED = TESTS / "fixtures" / "wheeled_arm.yaml"
#: the fixture's wheel: radius (m), reduction, rotor and wheel inertia about the axle (kg m^2)
RADIUS, REDUCTION, ROTOR, WHEEL = 0.05, 10.0, 1e-5, 0.000625
#: how far the arm swings in the lock-step run (rad)
SWING = 0.5


@pytest.fixture(scope="module")
def wheeled():
    return load_bus_config(WHEELED)


def test_a_wheel_on_the_floor_sees_the_robot_it_rolls_and_stays_finite(wheeled):
    """Rolling without slipping, the wheel motor moves its rotor, its wheel and a share of
    the robot's mass at the wheel's radius: more than the wheel alone (spinning in the
    air), less than the whole robot on that one wheel."""
    plant = bench_plant(wheeled)
    assert set(plant.resting_points()) == {plant.model.body(name).id
                                           for name in ("left_wheel", "right_wheel", "caster")}
    inertias = plant.motor_inertias()
    alone = ROTOR + WHEEL / REDUCTION ** 2
    whole = alone + float(plant.model.body_subtreemass[plant.base_body]) * RADIUS ** 2 \
        / REDUCTION ** 2
    for wheel in ("left_wheel_motor", "right_wheel_motor"):
        assert 2 * alone < inertias[wheel] < whole
    assert inertias["left_wheel_motor"] == pytest.approx(inertias["right_wheel_motor"], rel=1e-3)
    assert all(math.isfinite(value) and value > 0 for value in inertias.values())


def test_the_same_robot_with_a_fixed_base_sees_its_wheels_alone(wheeled):
    inertias = Plant(wheeled.robot).motor_inertias()
    assert inertias["left_wheel_motor"] == pytest.approx(ROTOR + WHEEL / REDUCTION ** 2)


@pytest.mark.parametrize("inertia", [math.inf, math.nan, 0.0, -1e-5])
def test_a_drive_tuned_on_an_inertia_that_is_not_finite_and_positive_is_refused(wheeled,
                                                                                 inertia):
    drive = wheeled.drives[0]
    with pytest.raises(HilError) as refused:
        drive_parameters(drive, inertia)
    text = str(refused.value)
    assert "node 1 (left_wheel_joint)" in text and "gains" in text


def test_wheels_made_revolute_joints_are_feet_that_lock_and_hil_sim_refuses_them(tmp_path):
    """Wheels as revolute joints are not wheels to hil (docs/configuration.md: a wheel is a
    continuous joint): pinned where they rest beside the caster they cannot turn, their
    motors' inertia is infinite, and the simulator refuses to tune them, naming the drive,
    before any drive runs."""
    urdf = (WHEELED.parent / "wheeled_arm.urdf").read_text().replace(
        'type="continuous"', 'type="revolute"').replace(
        '<limit effort="5"', '<limit lower="-100" upper="100" effort="5"')
    (tmp_path / "wheeled_arm.urdf").write_text(urdf)
    (tmp_path / "bench.yaml").write_text(WHEELED.read_text())
    config = load_bus_config(tmp_path / "bench.yaml")
    assert bench_plant(config).motor_inertias()["left_wheel_motor"] == math.inf
    bus = can.Bus(interface="virtual", channel="hil_test_locked_wheels")
    try:
        with pytest.raises(HilError) as refused:
            Simulator(config, {"base": bus}, LOCK_STEP)
    finally:
        bus.shutdown()
    text = str(refused.value)
    assert "drive node 1 (left_wheel_joint): hil cannot tune its loops" in text
    assert "inf kg" in text and "gains" in text


def test_a_lock_step_bench_on_wheels_enables_its_drives_and_swings_its_arm(wheeled):
    """On main the wheel motors' inertia came out infinite (the resting caster and wheels
    pinned where they stand lock the wheels), velocity_kp inf, and the controller refused
    the drives for implausible feedback."""
    with running_stack(wheeled, LOCK_STEP) as stack:
        plant = stack.sim.plant
        with stack.sim.lock:
            start = plant.joint_positions().copy()
        names = plant.joint_names
        goal_positions = start + np.array([SWING if name == "shoulder" else 0.0
                                           for name in names])
        goal = TrajectoryGoal(names, (
            TrajectoryPoint(1.0, tuple(goal_positions), (0.0,) * len(names)),
            TrajectoryPoint(1.5, tuple(goal_positions), (0.0,) * len(names))))
        client = TrajectoryActionClient(stack.zenoh, wheeled.robot.name)
        try:
            result = client.wait_result(client.send_goal(goal), timeout=120)
        finally:
            client.close()
        assert result is not None and result.error_code == 0, result
        with stack.sim.lock:
            ended = plant.joint_positions()
            velocities_finite = np.isfinite(plant.data.qvel).all()
    assert velocities_finite
    shoulder = names.index("shoulder")
    assert ended[shoulder] - start[shoulder] == pytest.approx(SWING, abs=0.02)
    for wheel in ("left_wheel_joint", "right_wheel_joint"):      # held where they were
        assert ended[names.index(wheel)] == pytest.approx(start[names.index(wheel)], abs=0.05)
