"""The MuJoCo plant: seed robots compile, transmissions act in physics."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from hil.plant import Plant


@pytest.fixture
def ur3_plant(ur3):
    return Plant(ur3)


@pytest.fixture
def pigot_plant(pigot):
    return Plant(pigot)


@pytest.fixture
def coupled_plant(coupled):
    return Plant(coupled)


UR3_POSE = dict(joint1=0.3, joint2=-0.8, joint3=1.1, joint4=-0.4, joint5=0.6, joint6=0.2)
UR3_REDUCTION = np.array([120, 120, 120, 100, 100, 100.0])


def test_seed_robots_compile_with_joint_count_limits_and_masses(ur3_plant, pigot_plant):
    ur3 = ur3_plant.model
    assert (ur3.njnt, ur3.nu, ur3.neq) == (6, 6, 0)
    assert ur3.body_mass.sum() == pytest.approx(5.50989)
    assert np.allclose(ur3.jnt_range, [[-3.14, 3.14]] * 6)
    pigot = pigot_plant.model
    assert (pigot.njnt, pigot.nu, pigot.neq) == (8, 7, 1)
    assert pigot.body_mass.sum() == pytest.approx(29.628908)
    assert pigot.jnt_range[pigot.joint("arm_rot_5").id].tolist() == [-3.1415, 0.0]
    assert pigot.jnt_type[pigot.joint("finger_pri_1").id] == mujoco.mjtJoint.mjJNT_SLIDE
    assert pigot.dof_damping[pigot.joint("arm_rot_1").dofadr[0]] == pytest.approx(0.1)
    assert pigot.dof_frictionloss[pigot.joint("arm_rot_1").dofadr[0]] == pytest.approx(0.1)


def test_link_inertia_is_the_urdf_tensor(ur3_plant):
    """MuJoCo diagonalises the tensor; its eigenvalues must be the URDF tensor's."""
    model = ur3_plant.model
    body = model.body("link1").id
    urdf = np.array([[0.0010675, -9.4953e-08, 1.0255e-07],
                     [-9.4953e-08, 0.00090525, -0.00013058],
                     [1.0255e-07, -0.00013058, 0.00099003]])
    assert sorted(model.body_inertia[body]) == pytest.approx(sorted(np.linalg.eigvalsh(urdf)))


def test_simple_transmission_is_joint_gear_with_reflected_rotor_inertia(ur3_plant):
    model = ur3_plant.model
    assert model.actuator_gear[:, 0].tolist() == UR3_REDUCTION.tolist()
    assert model.dof_armature == pytest.approx([1.5e-5 * 120**2] * 3 + [1e-5 * 100**2] * 3)
    # motor torque range = effort limit / reduction
    assert model.actuator_ctrlrange[:, 1] == pytest.approx(100.0 / UR3_REDUCTION)


def test_actuator_length_is_motor_position(ur3_plant):
    ur3_plant.set_joint_positions(UR3_POSE)
    expected = np.array(list(UR3_POSE.values())) * UR3_REDUCTION
    assert ur3_plant.motor_positions() == pytest.approx(expected)
    assert ur3_plant.data.actuator_length == pytest.approx(expected)


def test_holding_ur3_still_needs_inverse_dynamics_over_reduction(ur3_plant):
    ur3_plant.set_joint_positions(UR3_POSE)
    ur3_plant.data.qacc[:] = 0.0
    joint_torques = ur3_plant.inverse_dynamics()
    assert np.abs(joint_torques).max() > 1.0  # a pose that gravity loads
    ur3_plant.set_motor_torques(joint_torques / UR3_REDUCTION)
    start = ur3_plant.joint_positions()
    ur3_plant.step(1000)
    assert ur3_plant.joint_positions() == pytest.approx(start, abs=1e-6)
    assert ur3_plant.joint_efforts() == pytest.approx(joint_torques)


def test_without_holding_torque_the_ur3_falls(ur3_plant):
    """Counterpart of the hold test: the pose really is loaded by gravity."""
    ur3_plant.set_joint_positions(UR3_POSE)
    start = ur3_plant.joint_positions()
    ur3_plant.step(200)
    assert np.abs(ur3_plant.joint_positions() - start).max() > 1e-2


def test_motor_torque_saturates_at_effort_limit(ur3_plant):
    ur3_plant.set_motor_torques(np.full(6, 50.0))
    ur3_plant.step()
    assert ur3_plant.motor_torques() == pytest.approx(100.0 / UR3_REDUCTION)


def test_mimic_finger_follows_the_driving_finger(pigot_plant):
    pigot_plant.model.opt.gravity[:] = 0.0
    finger = list(pigot_plant.actuator_names).index("finger_pri_1_motor")
    torques = np.zeros(len(pigot_plant.actuator_names))
    torques[finger] = 1e-4  # N·m on the lead screw: ~0.3 N on the finger
    pigot_plant.set_motor_torques(torques)
    pigot_plant.step(300)
    q = dict(zip(pigot_plant.joint_names, pigot_plant.joint_positions()))
    assert q["finger_pri_1"] > 0.005
    assert q["finger_pri_2"] == pytest.approx(q["finger_pri_1"], abs=2e-4)


def test_coupled_transmissions_act_in_the_plant(coupled_plant):
    plant = coupled_plant
    four_bar, differential = plant.transmissions
    assert plant.model.ntendon == 4
    q = dict(shoulder=0.4, elbow=-0.3, wrist_pitch=0.2, wrist_roll=0.7)
    plant.set_joint_positions(q)
    qv = np.array(list(q.values()))
    expected = np.concatenate([four_bar.joint_to_actuator_position(qv[:2]),
                               differential.joint_to_actuator_position(qv[2:])])
    assert plant.motor_positions() == pytest.approx(expected)
    # motor torques reach the joints through P^T (virtual work), which for the
    # differential equals ros2_control's effort map
    tau_a = np.array([0.05, -0.1, 0.2, 0.1])
    plant.set_motor_torques(tau_a)
    plant.step()
    joint_efforts = plant.joint_efforts()
    assert joint_efforts[:2] == pytest.approx(four_bar.position_matrix.T @ tau_a[:2])
    assert joint_efforts[2:] == pytest.approx(differential.actuator_to_joint_effort(tau_a[2:]))


def test_coupled_rotor_inertia_reflects_as_p_transpose_j_p(coupled_plant):
    plant = coupled_plant
    plant.model.opt.gravity[:] = 0.0
    plant.set_joint_positions({})
    mass = np.zeros((plant.model.nv, plant.model.nv))
    mujoco.mj_fullM(plant.model, plant.data, mass)
    bare = Plant(plant.description)
    bare.model.tendon_armature[:] = 0.0
    mujoco.mj_forward(bare.model, bare.data)
    bare_mass = np.zeros_like(mass)
    mujoco.mj_fullM(bare.model, bare.data, bare_mass)
    p = plant.transmissions[1].position_matrix
    assert (mass - bare_mass)[2:, 2:] == pytest.approx(p.T @ np.diag([5e-6, 5e-6]) @ p)
