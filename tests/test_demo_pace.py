"""The demo paces itself by what the joints can give: slowed until its motion takes no joint
more than MOTION_SHARE of its effort limit, and a joint gravity alone overloads is named."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import ROOT
from hil.bus_config import load_bus_config
from hil.commissioning.demo_pace import MOTION_SHARE, demo_loads, paced_demo
from hil.controllers.demo import demo_goal
from hil.description import PackagePath, load_description
from hil.plant import Plant


def _slider(tmp_path, axis: str, mass: float, effort: float):
    """A base on a 2 m slider along ``axis`` carrying ``mass`` kg (a mobile base, a lift)."""
    path = tmp_path / "slider.urdf"
    path.write_text(f'''<robot name="slider">
  <link name="ground"/>
  <link name="carriage"><inertial><mass value="{mass}"/><inertia ixx="1" ixy="0" ixz="0"
    iyy="1" iyz="0" izz="1"/></inertial></link>
  <joint name="slide" type="prismatic"><parent link="ground"/><child link="carriage"/>
    <axis xyz="{axis}"/><limit lower="-1" upper="1" effort="{effort}" velocity="1"/></joint>
</robot>''')
    return load_description(path, PackagePath(()))


def test_a_demo_too_quick_for_the_effort_limit_is_slowed_until_its_motion_fits(tmp_path):
    robot = _slider(tmp_path, "1 0 0", mass=20.0, effort=10.0)     # horizontal: no gravity
    plant = Plant(robot)
    quick = demo_loads(plant, demo_goal(robot, ["slide"], [0.0]), [0.0])
    assert quick.peak["slide"] > MOTION_SHARE * 10.0      # as the velocity limit paces it
    paced = paced_demo(robot, ["slide"], [0.0])
    assert paced.slower > 1.0 and not paced.notes
    assert paced.loads.peak["slide"] == pytest.approx(MOTION_SHARE * 10.0, rel=0.25)
    assert paced.loads.peak["slide"] <= MOTION_SHARE * 10.0 * 1.01
    assert paced.goal.points[-1].time_from_start > \
        demo_goal(robot, ["slide"], [0.0]).points[-1].time_from_start


def test_a_joint_gravity_alone_overloads_is_named_not_slowed_for(tmp_path):
    robot = _slider(tmp_path, "0 0 1", mass=20.0, effort=100.0)    # a lift: 196 N to hold
    paced = paced_demo(robot, ["slide"], [0.0])
    assert paced.slower == 1.0
    assert paced.loads.holding["slide"] == pytest.approx(20.0 * 9.81, rel=1e-3)
    (note,) = paced.notes
    assert "joint 'slide' needs" in note and "gravity alone 196" in note


def test_a_robot_within_its_limits_runs_the_demo_as_its_velocity_limits_pace_it():
    config = load_bus_config(ROOT / "bus_config" / "ur3.yaml")
    names = [j for d in config.drives for j in d.joints]
    paced = paced_demo(config.robot, names, np.zeros(len(names)))
    assert paced.slower == 1.0 and not paced.notes
