"""A first bus config for any robot description: what ``hil init`` writes.

One drive per actuated joint: the description's own transmissions where it has them, else
a simple transmission per movable, non-mimic joint sized by :mod:`hil.commissioning.sizing`
and carried by the config (``transmissions:``), so the description stays untouched; a joint
the description gives no effort or velocity limit gets sizing's default class, carried by
the config too (``joint_limits:``). The
drives are spread over as many 1 Mbit/s buses as the load check allows at the rate, with
node ids from 1: classical buses, or CAN FD ones with a 5 Mbit/s data phase (``fd``, for a
family whose drives speak FD; always for one that speaks nothing else), as OpenArm's and
moteus' benches run them. Comments in the file say what was assumed.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, replace
from datetime import date
from pathlib import Path

import mujoco
import numpy as np

from hil.commissioning.demo_pace import paced_demo
from hil.commissioning.drive_options import STANCE_BANDWIDTH_HZ, Drive, with_options
from hil.commissioning.stance import Stance, stance, standing_pose
from hil.commissioning.sizing import (
    MOTOR_CLASSES, Sizing, default_limits, models_catalogue, needs_default_limits, size_joint,
)
from hil.bus_config.bus_entry import DEFAULT_DATA_BITRATE
from hil.bus_config.joint_limits import KEYS as LIMIT_KEYS
from hil.bus_config.transmissions import SIMPLE, actuator_of
from hil.bus_config.types import LOAD_WARNING, Gains
from hil.can import bus_load
from hil.description import (
    WORLD, Joint, JointLimits, RobotDescription, TransmissionActuator, TransmissionJoint,
    TransmissionSpec,
)
from hil.plant import Plant
from hil.protocols import protocol
from hil.protocols.base import CanFd, Protocol

BITRATE = 1_000_000
HEARTBEAT_PERIOD = 0.1
@dataclass(frozen=True)
class DefaultedJoint:
    """A joint given the default class: the limits written, and what the description had."""

    joint: str
    limits: JointLimits
    note: str


@dataclass(frozen=True)
class InitialConfig:
    text: str
    drives: int
    buses: int
    defaulted: tuple[DefaultedJoint, ...]
    standing: Stance | None = None      # a floating base, standing so
    notes: tuple[str, ...] = ()         # what the drives cannot do that the demo asks


def initial_config(robot: RobotDescription, description: Path, output: Path,
                   protocol_name: str, rate: float, motor: str | None = None,
                   gains: Mapping[str, Gains] | None = None, fd: bool = False
                   ) -> InitialConfig:
    """The YAML text of a bus config for ``robot`` (read from ``description``), to be
    written at ``output``: a drive for every joint of ``robot.undriven_joints``; a robot
    that stands (:mod:`hil.commissioning.stance`) gets a floating base, a standing start
    pose and a floor, and drives that hold it standing. ``motor``: the product every drive
    is (a key of the protocol's ``models``), else the smallest of them that fits each;
    ``gains``: the drives' loop gains to write, by actuator (:mod:`hil.commissioning.
    coupled_loops`), else ``hil sim`` tunes them; ``fd``: CAN FD buses (ValueError for a
    family that speaks only classical CAN; a family that speaks only FD gets them anyway)."""
    spec = protocol(protocol_name)
    if fd and spec.can_fd is CanFd.CLASSIC:
        raise ValueError(f"{protocol_name} drives speak classical CAN only: no FD bus for them")
    fd = fd or spec.can_fd is CanFd.FD_ONLY
    worst = worst_gravity_loads(robot)
    defaulted = tuple(_defaulted(j, worst[j.name]) for j in robot.undriven_joints
                      if needs_default_limits(j))
    limited = {d.joint: d.limits for d in defaulted}
    robot = replace(robot, joints=tuple(replace(j, limits=limited[j.name]) if j.name in limited
                                        else j for j in robot.joints))
    standing, pose = stands(robot)
    holding = demo_holding_loads(robot, pose)
    if standing is not None:
        holding = {name: max(load, standing.loads.get(name, 0.0))
                   for name, load in holding.items()}
    catalogue = (models_catalogue(spec.models[m] for m in (motor,) if m) if motor
                 else models_catalogue(spec.models.values()) if spec.models else MOTOR_CLASSES)
    sizings = [size_joint(joint, holding[joint.name], catalogue)
               for joint in robot.undriven_joints]
    added = tuple(_transmission(s) for s in sizings)
    sized = replace(robot, transmissions=robot.transmissions + added)
    drives = [Drive(t.joints[0].name if len(t.joints) == 1 else ", ".join(j.name for j in t.joints),
                    a.name, None, None) for t in robot.transmissions for a in t.actuators]
    drives += [Drive(s.joint, actuator_of(s.joint), s,
                     min(s.motor.rated_torque, sized.joint(s.joint).limits.effort / s.reduction))
               for s in sizings]
    drives, notes = with_options(sized, drives, spec, catalogue, holding,
                                 standing.loads if standing is not None else {})
    drives = [replace(d, gains=(gains or {}).get(d.actuator)) for d in drives]
    if standing is not None:
        carrying = set(standing.carrying)
        drives = [replace(d, velocity_bandwidth_hz=STANCE_BANDWIDTH_HZ)
                  if carrying & {j.strip() for j in d.joint.split(",")} else d for d in drives]
    per_bus = _drives_per_bus(spec, rate, fd)
    buses = [drives[i:i + per_bus] for i in range(0, len(drives), per_bus)]
    text = _yaml(robot, description, output, protocol_name, rate, sizings, buses, per_bus,
                 defaulted, standing, pose, fd)
    return InitialConfig(text, len(drives), len(buses), defaulted, standing, tuple(notes))


def stands(robot: RobotDescription) -> tuple[Stance | None, dict[str, float]]:
    """How the robot stands, if it does, and the start pose it stands in: its feet under its
    hips (:func:`~hil.commissioning.stance.standing_pose`) where it stands so too, else the
    pose it starts in."""
    found = stance(robot)
    if found is None:
        return None, {}
    pose = standing_pose(robot, found)
    again = stance(robot, pose)
    return (again, pose) if again is not None else (found, {})


def demo_holding_loads(robot: RobotDescription, start_pose: dict[str, float] | None = None
                       ) -> dict[str, float]:
    """The largest gravity load each joint that gets a drive holds along the demo `hil up
    --demo` runs from the start pose (N·m or N), on a fixed base."""
    names = [j.name for t in robot.transmissions for j in t.joints]
    names += [j.name for j in robot.undriven_joints]
    if not names:
        return {}
    return paced_demo(robot, names, start_pose=start_pose).loads.holding


def worst_gravity_loads(robot: RobotDescription) -> dict[str, float]:
    """Each movable joint's largest gravity load in any of its own positions (N·m or N),
    the rest of the robot at the start pose: the weight of all it carries, times (for a
    rotary joint) the distance of that weight's centre from its axis."""
    plant = Plant(robot)
    model, data = plant.model, plant.data
    gravity = float(np.linalg.norm(model.opt.gravity))
    loads = {}
    for name in plant.joint_names:
        joint = model.joint(name)
        body = joint.bodyid[0]
        weight = float(model.body_subtreemass[body]) * gravity
        if joint.type[0] == mujoco.mjtJoint.mjJNT_SLIDE:
            loads[name] = weight
            continue
        arm = data.subtree_com[body] - data.xanchor[joint.id]
        axis = data.xaxis[joint.id]
        loads[name] = weight * float(np.linalg.norm(arm - (arm @ axis) * axis))
    return loads


def _defaulted(joint: Joint, worst_load: float) -> DefaultedJoint:
    limits = default_limits(joint, worst_load)
    given = joint.limits
    had = ("no <limit>" if given is None else
           f"effort {given.effort:g}, velocity {given.velocity:g}")
    unit = joint.type.effort_unit
    return DefaultedJoint(joint.name, limits,
                          f"the description gives {had}: hil's default class, "
                          f"{limits.effort:g} {unit} (its largest gravity load "
                          f"{abs(worst_load):.3g} {unit}), {limits.velocity:g} "
                          f"{joint.type.unit}/s")


def _transmission(sizing: Sizing) -> TransmissionSpec:
    return TransmissionSpec(
        name=f"{sizing.joint}_transmission", type=SIMPLE,
        joints=(TransmissionJoint(name=sizing.joint),),
        actuators=(TransmissionActuator(name=actuator_of(sizing.joint),
                                        reduction=sizing.reduction,
                                        rotor_inertia=sizing.motor.rotor_inertia),))


def _drives_per_bus(spec: type[Protocol], rate: float, fd: bool) -> int:
    """How many drives of the protocol fit on one bus (FD: with its data phase at
    DEFAULT_DATA_BITRATE) at ``rate`` under LOAD_WARNING."""
    data_bitrate = DEFAULT_DATA_BITRATE if fd else None
    one = [frame for frame in spec.on_bus(spec.bus_frames(spec.node_ids.start or 1, rate,
                                                          HEARTBEAT_PERIOD), fd)
           if frame.rate > 0]
    bus_wide = bus_load(BITRATE, [frame for frame in spec.bus_wide_frames(rate) if frame.rate > 0],
                        data_bitrate)
    per_drive = bus_load(BITRATE, one, data_bitrate).worst_bits_per_second
    budget = LOAD_WARNING * BITRATE - bus_wide.worst_bits_per_second
    return max(1, min(int(budget // per_drive), len(spec.node_ids) - 1))


def _number(value: float) -> str:
    """A float as YAML 1.1 (PyYAML) reads it back as one: ``1e-07`` is a string there."""
    text = f"{value:.4g}"
    mantissa, e, exponent = text.partition("e")
    return f"{mantissa}.0e{exponent}" if e and "." not in mantissa else text


def _number_at_most(value: float) -> str:
    """:func:`_number`, rounded down where rounding up would pass ``value``: a rated torque
    capped at the joint's effort limit must not come back above the peak the config
    derives from that limit at full precision."""
    text = _number(value)
    if value <= 0 or float(text) <= value:
        return text
    scale = 10.0 ** (3 - math.floor(math.log10(value)))
    return _number(math.floor(value * scale) / scale)


def _yaml(robot: RobotDescription, description: Path, output: Path, protocol_name: str,
          rate: float, sizings: list[Sizing], buses: list[list[Drive]], per_bus: int,
          defaulted: tuple[DefaultedJoint, ...], standing: Stance | None,
          pose: dict[str, float], fd: bool) -> str:
    robot_path = os.path.relpath(description.resolve(), output.resolve().parent)
    if robot_path.startswith(os.pardir):          # not below the config's folder
        robot_path = str(description.resolve())
    lines = [
        f"# Bus config for '{robot.name}', written by `hil init` on {date.today()}.",
        "# Check it, then: hil check THIS.yaml && hil up THIS.yaml --demo",
        "#",
        f"# Assumed: {protocol_name} drives, node ids from 1 on each bus, {len(buses)} "
        f"{'CAN FD ' if fd else ''}bus(es) of {BITRATE // 1000} kbit/s"
        f"{f' ({DEFAULT_DATA_BITRATE // 1000} kbit/s data)' if fd else ''} at {rate:g} Hz",
        f"# ({per_bus} drive(s) per bus keep the worst-case load under {LOAD_WARNING:.0%}).",
    ]
    if sizings:
        lines += [
            "# The description has no transmission for the joints under 'transmissions':",
            "# each gets a simple one, sized by hil's rule (hil/commissioning/sizing.py): the",
            "# smallest generic servo motor class whose peak torque x reduction covers the",
            "# joint's effort limit and whose top speed / reduction covers its velocity limit,",
            "# with the smallest such reduction. Replace them with your real drives' values.",
        ]
        if any(s.motor.inertia_estimated for s in sizings):
            lines += [f"# rotor_inertia: the {protocol_name} maker publishes none; hil's estimate, "
                      "the rotor of", "# a generic servo of the actuator's power times its "
                      "gear ratio squared", "# (sizing.py estimated_reflected_inertia)."]
    lines += ["", f"robot: {robot_path}", "plant_rate_hz: 1000"]
    if standing is not None:
        lines += ["", f"# The robot stands ({standing.kind}, on {', '.join(standing.feet)}): its "
                      "base is free and it", "# stands on a floor, in a pose with each foot under "
                      "its hip; the joints that carry it", "# hold it on their brakes until "
                      "the drives are enabled, and `hil up --demo` holds them;",
                  f"# their velocity loops run at {STANCE_BANDWIDTH_HZ:g} Hz, under the "
                  "contact with the ground.",
                  "base: floating"]
        if pose:
            lines += ["start_pose:"] + [f"  {name}: {_number(value)}"
                                        for name, value in pose.items()]
        lines += ["scene:", "  - {name: floor, shape: plane}"]
        if robot.root_link != WORLD:
            lines += ["", "# An IMU on the base, as a standing robot's balance needs one: "
                          "WitMotion's, on a", "# serial port beside this file (docs/sensors.md)",
                      "sensors:", f"  - {{name: imu, product: wit, link: {robot.root_link}, "
                      f"port: {robot.name}_imu, baud: 460800, rate_hz: 200}}"]
    if defaulted:
        lines += ["", "# No effort or velocity limit in the description: hil's default class",
                  "# (hil/commissioning/sizing.py). Replace them with the joints' real limits.",
                  "joint_limits:"]
        lines += [f"  {d.joint}: {{{LIMIT_KEYS[0]}: {_number(d.limits.effort)}, "
                  f"{LIMIT_KEYS[1]}: {_number(d.limits.velocity)}}}   # {d.note}"
                  for d in defaulted]
    if sizings:
        lines += ["", "transmissions:"]
        lines += [f"  {s.joint}: {{reduction: {s.reduction:.6g}, rotor_inertia: "
                  f"{_number(s.motor.rotor_inertia)}}}   # {s.note}" for s in sizings]
    if any(d.gravity_feed_forward for bus in buses for d in bus):
        lines += ["", "# torque_feed_forward: gravity where the drive holds its joint with the "
                      "master's PD alone,", "# no integral (MIT family): the master sends the "
                      "weight's torque from the description", "# (hil/commissioning/"
                      "drive_options.py)."]
    if any(d.gains is not None for bus in buses for d in bus):
        lines += ["", "# gains: where the drives' own loops, tuned on the least inertia each "
                      "motor sees,", "# would be unstable together (hil/commissioning/"
                      "coupled_loops.py)."]
    lines += ["", "defaults:", f"  protocol: {protocol_name}",
              "  encoder_counts_per_rev: 131072   # 17-bit encoder on the motor",
              "  # watchdog_timeout (s without commands before a drive stops): left to each",
              "  # protocol's default, the maker's where it documents one (hil init says which)",
              f"  heartbeat_period: {HEARTBEAT_PERIOD:g}", "", "buses:"]
    for number, drives in enumerate(buses, 1):
        node_id = 1
        lines += [f"  - name: bus{number}", "    interface: zenoh",
                  f"    channel: {robot.name}/bus{number}", f"    bitrate: {BITRATE}",
                  f"    cycle_hz: {rate:g}", "    drives:"]
        if fd:
            lines[-1:-1] = ["    fd: true", f"    data_bitrate: {DEFAULT_DATA_BITRATE}"]
        for drive in drives:
            key = (f"joint: {drive.joint}" if drive.sizing is not None
                   else f"actuator: {drive.actuator}")
            fields = [f"node_id: {node_id}", key]
            if drive.rated_torque is not None:
                fields.append(f"rated_torque: {_number_at_most(drive.rated_torque)}")
            if drive.gravity_feed_forward:
                fields.append("torque_feed_forward: gravity")
            if drive.velocity_bandwidth_hz is not None:
                fields.append(f"velocity_bandwidth_hz: {_number(drive.velocity_bandwidth_hz)}")
            if drive.gains is not None:
                fields.append("gains: {" + ", ".join(
                    f"{key}: {_number(getattr(drive.gains, key))}"
                    for key in ("position_kp", "velocity_kp", "velocity_ki")) + "}")
            if drive.options:
                fields.append("options: {" + ", ".join(
                    f"{k}: {v if isinstance(v, str) else _number(v)}"
                    for k, v in drive.options.items()) + "}")
            lines.append(f"      - {{{', '.join(fields)}}}")
            node_id += 1
    return "\n".join(lines) + "\n"


__all__ = ["DefaultedJoint", "InitialConfig", "initial_config"]
