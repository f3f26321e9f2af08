"""The seed robots load from xacro with their kinematics, limits and masses."""

from __future__ import annotations

import math
import os
import shutil
import subprocess
import sys

import pytest

from hil.description import JointType, PackagePath, load_description
from conftest import PIGOT_XACRO, ROOT, UR3_XACRO


def test_ur3_has_the_seed_joints_limits_and_masses(ur3):
    assert [j.name for j in ur3.movable_joints] == [f"joint{i}" for i in range(1, 7)]
    for joint in ur3.movable_joints:
        assert joint.type is JointType.REVOLUTE
        assert (joint.limits.lower, joint.limits.upper) == (-3.14, 3.14)
        assert (joint.limits.effort, joint.limits.velocity) == (100.0, 1.0)
    # masses of base_link, link1..link6 in seed 001
    assert ur3.total_mass == pytest.approx(1.371 + 0.75521 + 1.6559 + 0.96204 + 0.32519
                                           + 0.32519 + 0.11536)
    assert ur3.joint("joint6").origin.rpy == (1.5708, 0.2207, 3.1416)
    assert ur3.warnings == ()


def test_ur3_transmission_block_gives_each_joint_its_own_transmission(ur3):
    assert [t.name for t in ur3.transmissions] == [f"joint{i}_trans" for i in range(1, 7)]
    assert [a.name for a in ur3.actuators] == [f"joint{i}_motor" for i in range(1, 7)]
    assert [a.reduction for a in ur3.actuators] == [120, 120, 120, 100, 100, 100]
    assert all(a.rotor_inertia > 0 for a in ur3.actuators)


def test_pigot_has_arm_gripper_mimic_and_body(pigot):
    movable = {j.name: j for j in pigot.movable_joints}
    assert list(movable) == [f"arm_rot_{i}" for i in range(1, 7)] + ["finger_pri_1",
                                                                     "finger_pri_2"]
    assert movable["finger_pri_1"].type is JointType.PRISMATIC
    assert movable["finger_pri_2"].mimic.joint == "finger_pri_1"
    assert pigot.joint("arm_base_joint").parent == "body_link"
    assert pigot.root_link == "body_link"
    # xacro properties motor_torque / motor_torque2 / motor_vec / motor_damp / motor_fric
    assert movable["arm_rot_1"].limits.effort == 500
    assert movable["arm_rot_4"].limits.effort == 1
    assert movable["arm_rot_3"].limits.lower == -3.1415
    assert movable["arm_rot_3"].limits.upper == 1.5708
    assert all(j.limits.velocity == 12.56 for j in movable.values())
    assert all(j.dynamics.damping == 0.1 and j.dynamics.friction == 0.1
               for j in movable.values())
    arm = (3.2045 + 1.9264 + 5.1205 + 4.0428 + 0.14194 + 0.093662 + 0.064062 + 2 * 0.017522)
    assert pigot.total_mass == pytest.approx(arm + 15.0)  # + the body link hil adds


def test_pigot_finger_lead_screw_reduction(pigot):
    finger = next(t for t in pigot.transmissions if t.joints[0].name == "finger_pri_1")
    assert finger.actuators[0].reduction == pytest.approx(2 * math.pi / 0.002)
    assert "finger_pri_2" not in {j.name for j in pigot.driven_joints}


def test_ros2_control_block_and_roles_are_read(coupled):
    differential = next(t for t in coupled.transmissions if t.name == "wrist_differential")
    assert differential.type == "transmission_interface/DifferentialTransmission"
    # written actuator2 first: ordered by role
    assert [a.name for a in differential.actuators] == ["wrist_left_motor", "wrist_right_motor"]
    assert [j.reduction for j in differential.joints] == [1.0, -1.0]
    four_bar = next(t for t in coupled.transmissions if t.name == "arm_four_bar")
    assert four_bar.joints[0].offset == 0.1
    assert [a.rotor_inertia for a in four_bar.actuators] == [2e-5, 1e-5]


def test_package_path_order_flag_then_environment_then_robots(tmp_path, monkeypatch):
    monkeypatch.setenv("HIL_PACKAGE_PATH", str(tmp_path / "env"))
    path = PackagePath.from_environment([str(tmp_path / "flag")])
    assert path.roots[0] == (tmp_path / "flag").resolve()
    assert path.roots[1] == (tmp_path / "env").resolve()
    assert path.roots[-1] == (ROOT / "robots").resolve()


def test_package_on_environment_path_shadows_robots(tmp_path, monkeypatch):
    copy = tmp_path / "ur3_description"
    shutil.copytree(ROOT / "robots" / "ur3_description", copy)
    text = (copy / "urdf" / "ur3.xacro").read_text().replace('name="ur3"', 'name="ur3_copy"')
    (copy / "urdf" / "ur3.xacro").write_text(text)
    (tmp_path / "top.xacro").write_text(
        '<robot name="top" xmlns:xacro="http://ros.org/wiki/xacro">'
        '<xacro:include filename="$(find ur3_description)/urdf/ur3.xacro"/></robot>')
    monkeypatch.setenv("HIL_PACKAGE_PATH", str(tmp_path))
    description = load_description(tmp_path / "top.xacro")
    assert str(description.source).endswith("top.xacro")
    assert len(description.movable_joints) == 6


@pytest.mark.parametrize("robot", [UR3_XACRO, PIGOT_XACRO], ids=["ur3", "pigot"])
def test_hil_check_prints_summary_of_seed_robot(robot):
    env = {k: v for k, v in os.environ.items() if k not in ("HIL_PACKAGE_PATH",
                                                           "AMENT_PREFIX_PATH")}
    result = subprocess.run([sys.executable, "-m", "hil", "check", str(robot)],
                            capture_output=True, text=True, env=env, timeout=120)
    assert result.returncode == 0, result.stderr
    assert "total mass" in result.stdout
    assert "reduction" in result.stdout and "MuJoCo:" in result.stdout
    assert "Traceback" not in result.stderr
