"""hil's pytest plugin: what a failed test keeps of its run (docs/testing.md, "In pytest:
fixtures"), run as a user runs it, in a folder of its own."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path
from xml.etree import ElementTree

import pytest

from conftest import ROOT

FAILING = '''
from hil.controllers import TrajectoryGoal, TrajectoryPoint
from hil.messaging.zenoh_api import TrajectoryActionClient


def test_a_move_then_a_failure(hil_stack):
    stack = hil_stack("ur3")
    client = TrajectoryActionClient(stack.zenoh, "ur3")
    goal = TrajectoryGoal(("joint3",), (TrajectoryPoint(0.2, (0.05,), (0.0,)),))
    client.wait_result(client.send_goal(goal), timeout=60)
    client.close()
    assert False, "the user's check"
'''


@pytest.mark.slow
def test_a_failed_hil_stack_test_keeps_a_recording_for_review_and_a_can_log_for_replay(
        tmp_path):
    """Issue 64: a failed test kept CAN logs only (a drives bench's), nothing `hil review`
    reads; a whole stack's test now keeps its run as `hil up` keeps one: run.rrd (the
    controller's cycles, faults and resets) and run.can.blf (channels numbered in the
    config's bus order), each listed with the command that reads it."""
    from hil.bus_config import load_bus_config
    from hil.replay import survey
    from hil.visualisation.review import review

    (tmp_path / "test_user.py").write_text(FAILING)
    report = tmp_path / "report.xml"
    path = f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider",
                           "-p", "no:randomly", f"--junitxml={report}", str(tmp_path)],
                          cwd=tmp_path, capture_output=True, text=True, timeout=280,
                          env={**os.environ, "PATH": path})
    assert done.returncode == 1 and "the user's check" in done.stdout, done.stdout[-3000:]
    section = done.stdout[done.stdout.index("hil artefacts"):]
    recording = Path(re.search(r"kept: (\S+run\.rrd)  \(hil review ", section).group(1))
    can_log = Path(re.search(r"kept: (\S+run\.can\.blf)  \(hil replay ", section).group(1))
    properties = {p.get("name"): p.get("value") for p in ElementTree.parse(report).iter(
        "property")}
    assert properties == {"hil_recording": str(recording), "hil_can_log": str(can_log)}
    (run,) = review([recording]).runs
    assert run.robot == "ur3" and run.cycles > 100 and set(run.joints) >= {"joint3"}
    found = survey(can_log, load_bus_config(ROOT / "bus_config" / "ur3.yaml"), {})
    assert set(found.channels.values()) == {0, 1} and found.cycles > 100


def test_a_bus_named_longer_than_a_file_name_is_logged_and_mapped_back_by_replay(hil_drives,
                                                                                  tmp_path):
    """Issue 65 item 13: a bus named over 255 bytes (NAME_MAX, a file name's most on Linux)
    made hil_drives fail with OSError (ENAMETOOLONG) opening its log BUS.blf. Its log is
    named by hil.can.log_files: the name cut and a hash of it, and hil replay maps the file
    back to its bus (two long names that begin alike kept apart)."""
    import yaml

    from hil.replay.log import ChannelMap

    config = yaml.safe_load((ROOT / "bus_config" / "ur3.yaml").read_text())
    config["robot"] = str(ROOT / "robots" / "ur3_description" / "urdf" / "ur3.xacro")
    long_names = ["arm-" + "ü" * 200, "arm-" + "ü" * 200 + "-wrist"]      # 404 bytes and more
    for bus, name in zip(config["buses"], long_names):
        bus["name"] = name
    path = tmp_path / "long_buses.yaml"
    path.write_text(yaml.safe_dump(config, allow_unicode=True))
    bench = hil_drives(path, lock_step=True)
    bench.close()                                     # the logs closed, their headers written
    logs = sorted((tmp_path / "hil-can-1").iterdir())
    assert len(logs) == 2 and all(len(os.fsencode(log.name)) <= 255 for log in logs), logs
    channels = ChannelMap(bench.config, {})
    buses = {channels.bus(log.stem, 1) for log in logs}
    assert buses == {0, 1} and not channels.unmatched


def test_a_robot_named_longer_than_a_file_name_runs_as_a_hil_stack(hil_stack, tmp_path):
    """Issue 65 item 13: a robot named over 255 bytes made hil_stack fail with OSError
    (ENAMETOOLONG) writing its viewer URDF ROBOT.urdf beside the kept recording; the file is
    named by hil.file_names (cut, and a hash of the name)."""
    import shutil

    description = tmp_path / "ur3_description"
    shutil.copytree(ROOT / "robots" / "ur3_description", description)
    xacro = description / "urdf" / "ur3.xacro"
    xacro.write_text(xacro.read_text().replace('<robot name="ur3"', '<robot name="'
                                               + "ur3-" + "r" * 300 + '"', 1))
    config = tmp_path / "long_robot.yaml"
    config.write_text((ROOT / "bus_config" / "ur3.yaml").read_text().replace(
        "../robots/ur3_description/urdf/ur3.xacro", str(xacro)))
    stack = hil_stack(config)
    assert stack.config.robot.name.startswith("ur3-rrr")
    kept = tmp_path / "hil-stack-1"
    assert {path.suffix for path in kept.iterdir()} >= {".rrd", ".blf", ".urdf"}
    assert all(len(os.fsencode(path.name)) <= 255 for path in kept.iterdir())
