"""Tracking: the full stack against MuJoCo's ideal position servo on the same reference."""

from __future__ import annotations

import math
import time

import mujoco
import numpy as np

from hil.bus_config import SystemConfig
from hil.controllers import TrajectoryGoal, TrajectoryPoint
from hil.messaging.samples import ControlSamples
from hil.messaging.zenoh_api import RunSubscriber, TrajectoryActionClient
from hil.plant import Plant
from hil.stack import running_stack
from hil.realtime.timing import LOCK_STEP


def tracking_goal(config: SystemConfig) -> TrajectoryGoal:
    """The fixed reference: every driven joint out by 0.3 rad (or 40 % of a prismatic
    range) in 1.5 s, back in 1.5 s, stopping at each end (cubic)."""
    names, ends = [], []
    for joint in config.robot.driven_joints:
        names.append(joint.name)
        lower, upper = joint.limits.lower, joint.limits.upper
        span = 0.3 if joint.type.is_rotational else 0.4 * (upper - lower)
        start = min(max(0.0, lower), upper)
        ends.append(start + span if start + span <= upper else start - span)
    zeros = (0.0,) * len(names)
    starts = tuple(min(max(0.0, j.limits.lower), j.limits.upper)
                   for j in config.robot.driven_joints)
    return TrajectoryGoal(tuple(names), (TrajectoryPoint(1.5, tuple(ends), zeros),
                                         TrajectoryPoint(3.0, starts, zeros)))


def tracking(config: SystemConfig) -> dict:
    """The full stack (lock-step) follows the goal; MuJoCo's position servo follows the
    same reference on the same model; both errors are measured at the joints."""
    goal = tracking_goal(config)
    with running_stack(config, LOCK_STEP) as stack:
        samples: list[ControlSamples] = []
        subscriber = RunSubscriber(stack.zenoh, config.robot.name, samples.append, lambda *_: None,
                                   lambda *_: None)
        client = TrajectoryActionClient(stack.zenoh, config.robot.name)
        # first bring every joint to the start of the reference
        start = TrajectoryGoal(goal.joint_names, (TrajectoryPoint(
            2.0, goal.points[-1].positions, (0.0,) * len(goal.joint_names)),))
        client.wait_result(client.send_goal(start), 120)
        first = stack.node.cycles
        goal_id = client.send_goal(goal)
        result = client.wait_result(goal_id, 120)
        time.sleep(0.3)
        subscriber.close()
        client.close()
    cycles = np.concatenate([np.arange(s.first_cycle, s.next_cycle) for s in samples])
    reference = np.concatenate([s.reference for s in samples])[cycles > first]
    position = np.concatenate([s.position for s in samples])[cycles > first]
    error = reference - position
    ideal = _ideal_servo(config, reference)
    return {"result": result.status.name.lower(), "joints": list(goal.joint_names),
            "rms": float(np.sqrt(np.mean(error ** 2))), "max": float(np.abs(error).max()),
            "ideal_servo_rms": float(np.sqrt(np.mean(ideal ** 2))),
            "ideal_servo_max": float(np.abs(ideal).max()),
            "rms_per_joint": [float(v) for v in np.sqrt(np.mean(error ** 2, axis=0))]}


def _ideal_servo(config: SystemConfig, reference: np.ndarray) -> np.ndarray:
    """Joint error of MuJoCo position actuators (kp = J w^2, kv = 2 J w at each drive's
    velocity bandwidth, motor torque limits kept) following ``reference`` (per cycle)."""
    plant = Plant(config.robot, timestep=1.0 / config.plant_rate_hz)
    model = plant.model
    inertia = plant.motor_inertias()
    for drive in config.drives:
        i = model.actuator(drive.actuator).id
        omega = 2 * math.pi * drive.velocity_bandwidth_hz
        kp, kv = inertia[drive.actuator] * omega ** 2, 2 * inertia[drive.actuator] * omega
        model.actuator_gainprm[i, 0] = kp
        model.actuator_biastype[i] = mujoco.mjtBias.mjBIAS_AFFINE
        model.actuator_biasprm[i, :3] = (0.0, -kp, -kv)
        model.actuator_ctrllimited[i] = 0
        model.actuator_forcelimited[i] = 1
        model.actuator_forcerange[i] = (-drive.peak_torque, drive.peak_torque)
    transmissions = plant.transmissions
    names = [j.name for j in config.robot.driven_joints]
    index = {name: i for i, name in enumerate(names)}
    plant.set_joint_positions(dict(zip(names, reference[0])))
    measured = [plant.joint_names.index(name) for name in names]
    errors = []
    for row in reference:
        motor = np.zeros(len(plant.actuator_names))
        for transmission in transmissions:
            joints = [index[j] for j in transmission.joints]
            values = transmission.joint_to_actuator_position(row[joints])
            for actuator, value in zip(transmission.actuators, values):
                motor[plant.actuator_names.index(actuator)] = value
        plant.set_motor_torques(motor)       # ctrl = the motor position reference
        plant.step(config.steps_per_cycle)
        errors.append(row - plant.joint_positions()[measured])
    return np.array(errors)

