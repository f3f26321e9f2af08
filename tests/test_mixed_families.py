"""A robot that mixes actuator families on its buses (issue 68 item 5; lerobot #4535 asks for
one robot of Damiao and Robstride motors): example-robot-data's Unitree G1 with Robstride
legs (29-bit private protocol) and Damiao arms and waist (11-bit MIT frames), the two
families sharing one bus where their identifiers are the same numbers in two formats."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest
import yaml

from conftest import example_robot_data
from hil.bus_config import load_bus_config
from hil.cli import main
from hil.description import PackagePath

SHARE = example_robot_data()
pytestmark = pytest.mark.skipif(SHARE is None, reason="example-robot-data is not installed "
                                "(it comes with the test extra: pip install -e '.[test]')")
G1 = (SHARE / "example-robot-data" / "robots" / "g1_description" / "urdf"
      / "g1_29dof_rev_1_0.urdf") if SHARE else None
LEG = re.compile(r"hip|knee|ankle")


def initialised(protocol: str, folder) -> dict:
    """What `hil init --protocol PROTOCOL` writes for the G1, read back."""
    path = folder / f"g1_{protocol}.yaml"
    assert main(["init", str(G1), "--protocol", protocol, "-o", str(path),
                 "--package-path", str(SHARE)]) == 0
    return yaml.safe_load(path.read_text())


@pytest.fixture(scope="module")
def mixed_g1(tmp_path_factory):
    """The G1 standing on a floor (as `hil init` stands it): its legs' Robstride drives on
    three buses, the last shared with the waist's three Damiao drives (Robstride ids 1-2 and
    Damiao ids 1-3 on one bus), its arms' Damiao drives on three more; transmissions and
    gains as `hil init` sizes them for each family."""
    folder = tmp_path_factory.mktemp("mixed")
    robstride, damiao = initialised("robstride", folder), initialised("damiao", folder)
    inits = {"robstride": robstride, "damiao": damiao}

    def drives_of(family):
        return {drive["joint"]: drive for bus in inits[family]["buses"]
                for drive in bus["drives"]}

    joints = list(damiao["transmissions"])
    legs = [j for j in joints if LEG.search(j)]
    waist = [j for j in joints if j.startswith("waist")]
    arms = [j for j in joints if not LEG.search(j) and j not in waist]
    # five drives a bus at 500 Hz keep the worst-case load under 80 % (hil check)
    layout = {"left_leg": (legs[:5], []), "right_leg": (legs[6:11], []),
              "ankles_waist": ([legs[5], legs[11]], waist)}
    layout.update({f"arms{n + 1}": ([], arms[i:i + 5])
                   for n, i in enumerate(range(0, len(arms), 5))})
    buses = []
    for name, (robstride_joints, damiao_joints) in layout.items():
        listed = [{**drives_of(family)[j], "node_id": n, "protocol": family}
                  for family, members in (("robstride", robstride_joints),
                                          ("damiao", damiao_joints))
                  for n, j in enumerate(members, 1)]
        buses.append({"name": name, "interface": "zenoh", "channel": f"g1_mixed/{name}",
                      "bitrate": 1000000, "cycle_hz": 500, "drives": listed})
    config = {"robot": str(G1), "plant_rate_hz": 1000, "base": damiao["base"],
              "scene": damiao["scene"],
              "transmissions": {j: (robstride if LEG.search(j) else damiao)["transmissions"][j]
                                for j in joints},
              "defaults": {"encoder_counts_per_rev": 131072, "heartbeat_period": 0.1},
              "buses": buses}
    path = folder / "g1_mixed.yaml"
    path.write_text(yaml.safe_dump(config, sort_keys=False))
    return path


def test_a_bus_of_robstride_and_damiao_drives_checks_and_describes_both_families(
        mixed_g1, capsys):
    """The shared bus: Robstride's 29-bit frames and Damiao's 11-bit ones of the same
    numbers (node 1 of each) are distinct frames; `hil describe` lists each family's own."""
    config = load_bus_config(mixed_g1, PackagePath((SHARE,)))
    shared = next(bus for bus in config.buses if bus.name == "ankles_waist")
    assert {d.protocol for d in shared.drives} == {"robstride", "damiao"}
    assert main(["describe", str(mixed_g1), "--package-path", str(SHARE)]) == 0
    described = capsys.readouterr().out
    section = described[described.index("bus 'ankles_waist'"):described.index("bus 'arms1'")]
    assert "node 1: left_ankle_roll_joint (robstride)" in section, section
    assert "node 1: waist_yaw_joint (damiao)" in section, section
    assert re.search(r"0x17FFF01 ext +8 B +500/s +master: motion control", section), section
    assert re.search(r"0x001 +8 B +500/s +master: command", section), section


@pytest.mark.slow
@pytest.mark.timeout(300)       # 25 s here beside a CI run (2026-12-06)
def test_the_mixed_g1_stands_and_runs_its_demo_under_hils_master(mixed_g1, tmp_path):
    """`hil up --demo` of the mixed G1, unedited: hil's own master drives both families in
    one cycle, the robot stands on its Robstride legs while every joint moves, and the demo
    succeeds. (Before Robstride's rotor inertia was estimated, hil init's Robstride gains
    were tuned on the links alone: the legs let the robot fall, an ankle stalled.)"""
    up = subprocess.run([sys.executable, "-m", "hil", "up", str(mixed_g1), "--demo",
                         "--lock-step", "--no-viewer", "--save", str(tmp_path / "g1.rrd"),
                         "--package-path", str(SHARE)],
                        capture_output=True, text=True, timeout=280, cwd=tmp_path)
    assert up.returncode == 0, up.stdout[-3000:] + up.stderr[-3000:]
    assert "hil up: demo succeeded" in up.stdout
