"""Torque feed-forward from gravity (a drive's ``torque_feed_forward: gravity``): the
master's model of the robot's weight, from the description alone, against MuJoCo's; the
torque each protocol's master sends with its setpoints; a drive whose master sends it holds
a loaded joint with nothing left for its loops' integral to carry."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest
import yaml

from hil.hardware.axis import AxisCommand
from hil.bus_config import load_bus_config
from hil.bus_config.types import DriveConfig
from hil.description import load_description
from hil.errors import HilError
from hil.hardware.gravity import GravityModel
from hil.plant import Plant
from hil.protocols.cia402.axis import Cia402Axis
from hil.protocols.mit import unpack_command
from hil.protocols.mit.axis import MitAxis
from hil.protocols.odrive import LAYOUT, Cmd
from hil.protocols.odrive.axis import ODriveAxis
from hil.stack import running_stack
from hil.realtime import LOCK_STEP
from conftest import ROOT

UR3 = ROOT / "bus_config" / "ur3.yaml"


def bias_at_leaders(plant: Plant, names, positions: dict[str, float]) -> np.ndarray:
    """MuJoCo's gravity bias (qfrc_bias at rest) of each named joint, its mimic followers'
    carried by it (virtual work)."""
    plant.set_joint_positions(positions)
    model, bias = plant.model, plant.data.qfrc_bias
    loads = []
    for name in names:
        load = bias[model.joint(name).dofadr[0]]
        for joint in plant.description.joints:
            if joint.mimic is not None and joint.mimic.joint == name:
                load += joint.mimic.multiplier * bias[model.joint(joint.name).dofadr[0]]
        loads.append(load)
    return np.array(loads)


@pytest.mark.parametrize("robot", ["ur3", "pigot", "coupled"])
def test_the_masters_gravity_model_is_mujocos_at_any_pose(robot, request):
    description = request.getfixturevalue(robot)
    names = [j.name for j in description.driven_joints]
    model = GravityModel(description, names)
    plant = Plant(description)
    rng = np.random.default_rng(7)
    for _ in range(10):
        pose = {}
        for name in names:
            limits = description.joint(name).limits
            low, high = ((limits.lower, limits.upper) if limits and limits.lower is not None
                         else (-math.pi, math.pi))
            pose[name] = float(rng.uniform(low, high))
        expected = bias_at_leaders(plant, names, pose)
        np.testing.assert_allclose(model.torques([pose[n] for n in names]), expected,
                                   atol=1e-9)


#: an arm on a world link: a 2 kg link whose centre is 0.5 m out along x on a hinge about y,
#: and 1 m out a hinged tip with no inertial at all (which the description gives 1 g)
ARM_WITH_A_MASSLESS_TIP = """<robot name="arm">
  <link name="world"/>
  <link name="base"/>
  <joint name="fixed" type="fixed"><parent link="world"/><child link="base"/></joint>
  <link name="arm"><inertial><origin xyz="0.5 0 0"/><mass value="2"/>
    <inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="arm"/>
    <axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="50" velocity="2"/></joint>
  <link name="tip"/>
  <joint name="wrist" type="revolute"><parent link="arm"/><child link="tip"/>
    <origin xyz="1 0 0"/><axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="5" velocity="2"/></joint>
</robot>
"""


def test_the_gravity_model_holds_links_on_a_world_link_and_a_massless_tip(tmp_path):
    urdf = tmp_path / "arm.urdf"
    urdf.write_text(ARM_WITH_A_MASSLESS_TIP)
    description = load_description(urdf)
    tip = description.link("tip").inertial.mass
    model = GravityModel(description, ["shoulder", "wrist"])
    # the weights (2 kg at 0.5 m, the tip's at 1 m) turn the arm about +y (x towards -z):
    # held by -m g x
    np.testing.assert_allclose(model.torques([0.0, 0.0]), [-9.81 * (2 * 0.5 + tip), 0.0],
                               atol=1e-9)
    # turned down by 90 degrees the weight hangs under the hinge: nothing to hold
    np.testing.assert_allclose(model.torques([math.pi / 2, 1.0]), [0.0, 0.0], atol=1e-8)


def drive(protocol: str, options=None, torque_feed_forward: str = "gravity") -> DriveConfig:
    return DriveConfig(node_id=3, actuator="m", joints=("j",), protocol=protocol,
                       encoder_counts_per_rev=4096, rated_torque=2.0, peak_torque=6.0,
                       max_velocity=100.0, following_error_limit=0.5,
                       following_error_timeout=0.01, quick_stop_deceleration=100.0,
                       watchdog_timeout=0.1, heartbeat_period=0.1, holding_brake=True,
                       position_limits=None, gains=None, velocity_bandwidth_hz=40.0,
                       options=options, torque_feed_forward=torque_feed_forward)


def test_each_protocols_master_sends_the_torque_in_its_own_field(monkeypatch):
    cia402 = Cia402Axis(drive("cia402"), "bus")
    cia402.take_statusword(0x0027)                     # OPERATION ENABLED (CiA 402)
    frames = {f.identifier: f.data for f in cia402.cycle_frames(AxisCommand(1.0, 0.0, 1.5))}
    assert int.from_bytes(frames[0x503][4:6], "little", signed=True) == 750   # 1.5 / 2.0 ‰
    odrive = ODriveAxis(drive("odrive"), "bus")
    monkeypatch.setattr(ODriveAxis, "enabled", property(lambda self: True))
    sent = {f.identifier: f.data for f in odrive.cycle_frames(AxisCommand(1.0, 0.0, 1.5))}
    (_, _, torque_ff), = [LAYOUT[Cmd.SET_INPUT_POS].unpack(d) for i, d in sent.items()
                          if i == (3 << 5) | Cmd.SET_INPUT_POS]
    assert torque_ff == 1500                                           # 0.001 N·m
    config = load_bus_config(ROOT / "bus_config" / "pigot_mixed.yaml")
    mit_drive = next(d for d in config.drives if d.protocol == "mit")
    mit = MitAxis(DriveConfig(**{**mit_drive.__dict__, "torque_feed_forward": "gravity"}),
                  "bus")
    mit.motor_mode = True
    frame, = mit.cycle_frames(AxisCommand(0.1, 0.0, 0.4))
    assert unpack_command(frame.data, mit_drive.options.ranges).torque == pytest.approx(
        0.4, abs=0.01)


def test_a_cia402_drive_with_torque_feed_forward_maps_rpdo4_and_counts_its_load(tmp_path):
    data = yaml.safe_load(UR3.read_text())
    data["robot"] = str((UR3.parent / data["robot"]).resolve())
    data["defaults"]["torque_feed_forward"] = "gravity"
    path = tmp_path / "ur3.yaml"
    path.write_text(yaml.safe_dump(data))
    fed = load_bus_config(path)
    plain = load_bus_config(UR3)
    assert all(d.torque_feed_forward == "gravity" for d in fed.drives)
    assert fed.buses[0].load().frames_per_second == pytest.approx(
        plain.buses[0].load().frames_per_second + 3 * 500)            # RPDO4 per drive
    data["defaults"]["torque_feed_forward"] = "inertia"
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(HilError, match="torque_feed_forward is one of none, gravity, not "
                                       "'inertia'"):
        load_bus_config(path)


def integral_holding(config) -> list[float]:
    """Each ur3 drive's loop integral (N·m) after holding its start pose 1 s in lock-step."""
    with running_stack(config, LOCK_STEP) as stack:
        cycles = stack.node.cycles
        while stack.node.cycles < cycles + round(config.cycle_hz):
            time.sleep(0.01)
        with stack.sim.lock:
            return [d.core._integral for d in stack.sim.drives]


def test_with_gravity_fed_forward_the_drives_loops_carry_no_weight(tmp_path):
    """Holding the ur3 still: without feed-forward the drives' integrals hold the arm's
    weight (the shoulder most of it), with it they hold next to nothing."""
    data = yaml.safe_load(UR3.read_text())
    data["robot"] = str((UR3.parent / data["robot"]).resolve())
    path = tmp_path / "plain.yaml"
    path.write_text(yaml.safe_dump(data))
    plain = integral_holding(load_bus_config(path))
    data["defaults"]["torque_feed_forward"] = "gravity"
    path = tmp_path / "fed.yaml"
    path.write_text(yaml.safe_dump(data))
    fed = integral_holding(load_bus_config(path))
    shoulder = int(np.argmax(np.abs(plain)))
    assert abs(plain[shoulder]) > 0.02                         # N·m at the motor
    assert abs(fed[shoulder]) < 0.05 * abs(plain[shoulder])
