"""``hil bench``, scale: what a cycle costs the simulator and the controller as the robot
grows, and the largest robot that holds a rate across processes on this machine.

The robots are made here, so that every size is the same kind of machine: ⌈N/6⌉ copies of
the shipped ur3 on one base (the last one cut short to make N joints), spread over the buses
``hil init`` gives them at the rate: below 1 kHz each joint a CiA 402 drive on classical
buses (four drives a bus at 500 Hz, nine at 250 Hz); from 1 kHz on a Damiao motor on CAN FD
buses of 1 and 5 Mbit/s (``hil init --fd``: seven a bus at 1 kHz), as OpenArm's arms and
the humanoids of issue 69 run them, where classical CANopen would need a bus for every two
drives. Each runs as ``hil bench``'s across-processes rows do (``hil sim``
+ ``hil control`` in real time, placed as ``hil up`` places them, no visualiser); the cost
of a cycle is each process' share of a CPU over the measured window divided by the rate. A
size holds a rate when its run had no fault and missed at most HOLDS_MISSED of its cycles.
Beside each, ``hil sim`` with a bare python-can master in ``hil control``'s place
(:mod:`hil.bench.bare_master`): what hil's own master costs over the least a master needs.
"""

from __future__ import annotations

import copy
import math
import xml.etree.ElementTree as ET
from collections.abc import Callable
from pathlib import Path

import yaml

from hil.bench.bare_master import bare_master_across_processes
from hil.bench.processes import stack_across_processes
from hil.bench.settings import DID_NOT_START, BenchSettings
from hil.commissioning.initial import initial_config
from hil.description import load_description
from hil.description.packages import PackagePath
from hil.description.source import read_robot_source
from hil.resources import ROBOTS, data_dir

#: the arm the robots are made of (6 joints, each with its transmission)
ARM = Path("ur3_description") / "urdf" / "ur3.xacro"
JOINTS_PER_ARM = 6
#: the arms stand on a grid this far apart (m), three in a row
ARM_SPACING = 0.8
#: a run holds its rate with at most this share of its cycles missed (and no fault)
HOLDS_MISSED = 0.001
#: from this rate on the sweep's drives are Damiao motors on CAN FD buses (the module doc)
FD_FROM_HZ = 1000.0
#: the attributes that name a link, joint, transmission or actuator of the arm
_NAME_ATTRIBUTES = ("name", "link", "joint", "reference")


def scale(settings: BenchSettings, folder: Path, say: Callable[[str], None]) -> list[dict]:
    """A row per (drives, rate) of ``settings``: the made robot's buses, each process' CPU
    per cycle, the run's figures and whether it held the rate."""
    rows = []
    for rate in settings.scale_rates:
        for drives in settings.scale_drives:
            say(f"hil bench: scale, {drives} drives at {rate:g} Hz across processes ...")
            config, buses = scale_bench(drives, rate, folder)
            protocol_name, fd = sweep_drives(rate)
            run = stack_across_processes(config, settings.seconds, False)
            say(f"hil bench: scale, {drives} drives at {rate:g} Hz, a bare python-can master "
                "in hil control's place ...")
            bare = _bare_row(bare_master_across_processes(config, settings.seconds), rate)
            if DID_NOT_START in run:
                rows.append({"drives": drives, "rate_hz": rate, "buses": buses,
                             "protocol": protocol_name, "fd": fd, "holds": False,
                             DID_NOT_START: run[DID_NOT_START], "bare_master": bare})
                continue
            cycles = max(run.get("cycles", 0), 1)
            missed = run.get("missed", 0)
            rows.append({"drives": drives, "rate_hz": rate, "buses": buses,
                         "protocol": protocol_name, "fd": fd,
                         "cycles": run.get("cycles", 0), "missed": missed,
                         "faults": run["faults"], "first_fault": run["first_fault"],
                         "busy_p50_us": run.get("busy_p50_us", math.nan),
                         "busy_p99_us": run.get("busy_p99_us", math.nan),
                         "round_trip_p99_us": run.get("round_trip_p99_us", math.nan),
                         "cpu": run["cpu"], "cpu_us_per_cycle": _per_cycle(run["cpu"], rate),
                         "holds": run["faults"] == 0 and missed <= HOLDS_MISSED * cycles,
                         "bare_master": bare})
    return rows


def _per_cycle(cpu: dict[str, float], rate: float) -> dict[str, float]:
    """Each process' CPU share over the measured window, at the rate's cycles a second, as
    microseconds a cycle."""
    return {name: share / rate * 1e6 for name, share in cpu.items()}


def _bare_row(run: dict, rate: float) -> dict:
    """The bare master's run (:mod:`hil.bench.bare_master`) as a scale row keeps it."""
    if DID_NOT_START in run:
        return run
    return {"cycles": run["cycles"], "missed": run["missed"],
            "round_trip_p99_us": run.get("round_trip_p99_us", math.nan), "late": run["late"],
            "cpu": run["cpu"], "cpu_us_per_cycle": _per_cycle(run["cpu"], rate),
            "drives": run["drives"], "enabled": run["enabled"]}


def largest_holding(rows: list[dict]) -> dict[float, int | None]:
    """Per rate, the most drives of a run that held it (None: no size did)."""
    return {rate: max((row["drives"] for row in rows if row["rate_hz"] == rate
                       and row["holds"]), default=None)
            for rate in dict.fromkeys(row["rate_hz"] for row in rows)}


def sweep_drives(rate: float) -> tuple[str, bool]:
    """The protocol of the sweep's drives at ``rate``, and whether their buses are FD."""
    return ("damiao", True) if rate >= FD_FROM_HZ else ("cia402", False)


def scale_bench(drives: int, rate: float, folder: Path) -> tuple[Path, int]:
    """A robot of ``drives`` joints made of ur3 arms, and the bus config ``hil init`` writes
    for it at ``rate`` (:func:`sweep_drives`), in ``folder``: the config's path and its number
    of buses."""
    protocol_name, fd = sweep_drives(rate)
    # Damiao motors carry their gear: the arms without the ur3's transmissions, so that hil
    # init sizes a model for each joint (the ur3's 100:1 and 120:1 would put a joint's
    # range far past what the MIT frames carry)
    description = folder / f"arms_{drives}_{protocol_name}.urdf"
    description.write_bytes(ET.tostring(arms_robot(drives, transmissions=not fd),
                                        xml_declaration=True))
    robot = load_description(description)
    output = folder / f"arms_{drives}_{rate:g}hz.yaml"
    written = initial_config(robot, description, output, protocol_name, rate, fd=fd)
    output.write_text(written.text)
    if fd:
        # hil's choice for the bench: the motors hold the arms on brakes until enabled, as
        # the ur3's drives do (Damiao's have none: in real time the free arms swung past
        # the range the MIT frames carry before a master enabled them, and a bare master
        # enabling at once found some motors in error)
        config = yaml.safe_load(output.read_text())
        config["defaults"]["holding_brake"] = True
        output.write_text(yaml.safe_dump(config, sort_keys=False))
    return output, written.buses


def arms_robot(drives: int, transmissions: bool = True) -> ET.Element:
    """The URDF of ``drives`` joints: ⌈drives/6⌉ ur3 arms on a fixed base, named ``a<k>_``
    each, the last arm's chain cut after its remaining joints; with the ur3's transmissions,
    or none."""
    if drives < 1:
        raise ValueError(f"a robot of {drives} drives")
    arm = read_robot_source(data_dir(ROBOTS) / ARM, PackagePath.from_environment()).root
    robot = ET.Element("robot", name=f"arms_{drives}")
    base = ET.SubElement(robot, "link", name="base")
    _box_inertial(base, mass=50.0, size=3.0)
    for index in range((drives + JOINTS_PER_ARM - 1) // JOINTS_PER_ARM):
        joints = min(JOINTS_PER_ARM, drives - index * JOINTS_PER_ARM)
        prefix = f"a{index + 1}_"
        for element in _arm_elements(arm, joints):
            if transmissions or element.tag != "transmission":
                robot.append(_prefixed(element, prefix))
        mount = ET.SubElement(robot, "joint", name=f"{prefix}mount", type="fixed")
        ET.SubElement(mount, "parent", link="base")
        ET.SubElement(mount, "child", link=f"{prefix}{_root_link(arm)}")
        row, column = divmod(index, 3)
        ET.SubElement(mount, "origin", xyz=f"{column * ARM_SPACING} {row * ARM_SPACING} 0",
                      rpy="0 0 0")
    return robot


def _arm_elements(arm: ET.Element, joints: int) -> list[ET.Element]:
    """The arm's links, joints and transmissions up to its ``joints``-th joint (in chain
    order from the root)."""
    chain = [j for j in arm.findall("joint") if j.get("type") != "fixed"][:joints]
    kept_joints = {j.get("name") for j in chain}
    links = {_root_link(arm)} | {j.find("child").get("link") for j in chain}
    kept = []
    for element in arm:
        if element.tag == "link" and element.get("name") in links:
            kept.append(element)
        elif element.tag == "joint" and element.get("name") in kept_joints:
            kept.append(element)
        elif element.tag == "transmission" and all(
                j.get("name") in kept_joints for j in element.findall("joint")):
            kept.append(element)
    return kept


def _root_link(arm: ET.Element) -> str:
    children = {j.find("child").get("link") for j in arm.findall("joint")}
    return next(link.get("name") for link in arm.findall("link")
                if link.get("name") not in children)


def _prefixed(element: ET.Element, prefix: str) -> ET.Element:
    """A copy of ``element`` with every name it gives or refers to prefixed."""
    copied = copy.deepcopy(element)
    for node in copied.iter():
        for attribute in _NAME_ATTRIBUTES:
            if attribute in node.attrib:
                node.set(attribute, prefix + node.get(attribute))
    return copied


def _box_inertial(link: ET.Element, mass: float, size: float) -> None:
    inertial = ET.SubElement(link, "inertial")
    ET.SubElement(inertial, "mass", value=str(mass))
    moment = mass * size * size / 6
    ET.SubElement(inertial, "inertia", ixx=str(moment), iyy=str(moment), izz=str(moment),
                  ixy="0", ixz="0", iyz="0")
