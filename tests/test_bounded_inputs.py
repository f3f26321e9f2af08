"""Every input surface bounded (issue 43): a YAML alias bomb, a config nested without end,
a FIFO or a device named as a file, a flood of made-up Zenoh senders, goals without end:
each answered with a clear error or a bounded memory, never a hang or a traceback."""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import can
import pytest

from hil.bus_config import load_bus_config
from hil.description import PackagePath, load_description
from hil.can.frame import Frame
from hil.can.link_account import MAX_SENDERS
from hil.can.zenoh_wire import Echo, Message
from hil.cli import main
from hil.controllers import GoalResult, GoalStatus
from hil.durations import parse_duration
from hil.errors import HilError
from hil.input_files import read_input_file
from hil.protocols.odrive import ODriveOptions
from hil.simulator import bench_plant
from hil.zenoh_session import ZenohSettings


def _alias_bomb(levels: int = 9) -> str:
    lines = ["a0: &a0 [x, x, x, x, x, x, x, x, x]"]
    lines += [f"a{i}: &a{i} [" + ", ".join([f"*a{i - 1}"] * 9) + "]" for i in range(1, levels)]
    return "\n".join(lines) + "\nrobot: 1\n"


def test_a_yaml_alias_bomb_is_refused_before_it_expands(tmp_path):
    config = tmp_path / "bomb.yaml"
    config.write_text(_alias_bomb())
    with pytest.raises(HilError, match="alias bomb") as raised:
        load_bus_config(config)
    assert len(str(raised.value)) < 2000


def test_a_config_nested_without_end_is_refused(tmp_path):
    config = tmp_path / "deep.yaml"
    config.write_text("a: " + "[" * 5000 + "]" * 5000 + "\n")
    with pytest.raises(HilError, match="nested"):
        load_bus_config(config)


def test_a_fifo_or_a_device_is_no_input_file(tmp_path):
    fifo = tmp_path / "config.yaml"
    os.mkfifo(fifo)
    with pytest.raises(HilError, match="not a regular file"):
        load_bus_config(fifo)                  # a read of a FIFO would wait for a writer
    with pytest.raises(HilError, match="not a regular file"):
        read_input_file("/dev/zero", "robot description", "give a file")


def test_a_long_value_in_a_diagnostic_is_cut(tmp_path):
    config = tmp_path / "long.yaml"
    config.write_text("robot: " + "x" * 100_000 + ".xacro\n")
    with pytest.raises(HilError) as raised:
        load_bus_config(config)
    assert len(str(raised.value)) < 2000


def _damiao_config(folder: Path, old: str, new: str) -> Path:
    """The one-axis Damiao config in ``folder``, ``old`` written as ``new``."""
    fixtures = Path(__file__).parent / "fixtures"
    shutil.copy(fixtures / "damiao_one_axis.urdf", folder)
    config = folder / "bus.yaml"
    config.write_text((fixtures / "damiao_one_axis.yaml").read_text().replace(old, new))
    return config


@pytest.mark.parametrize("cycle_hz, said", [
    ("fast", "must be a number, not 'fast'"),
    ("9" * 400, "must be > 0, not 999"),              # an int no float can hold
    ("9" * 5000, "a number of 5000 characters"),      # an int PyYAML cannot convert
])
def test_a_number_no_float_holds_is_an_error_not_a_traceback(tmp_path, cycle_hz, said):
    config = _damiao_config(tmp_path, "cycle_hz: 500", f"cycle_hz: {cycle_hz}")
    with pytest.raises(HilError, match="bus.yaml:12") as raised:
        load_bus_config(config)
    assert said in str(raised.value)


@pytest.mark.parametrize("option, said", [
    ("kd: " + "9" * 400, "int too large"),
    ("kd: fast", "could not convert"),
])
def test_a_drive_option_no_float_holds_is_an_error_not_a_traceback(tmp_path, option, said):
    config = _damiao_config(tmp_path, "kd: 0.3", option)
    with pytest.raises(HilError, match="bus.yaml:14.*options") as raised:
        load_bus_config(config)
    assert said in str(raised.value)


def test_an_odrive_message_rate_is_a_uint32_as_in_the_firmware():
    assert ODriveOptions.from_mapping({"encoder_msg_rate_ms": 2**32 - 1})
    with pytest.raises(ValueError, match="0..4294967295"):
        ODriveOptions.from_mapping({"encoder_msg_rate_ms": 2**32})


def test_a_bus_remembers_a_bounded_number_of_senders(tmp_path):
    bus = can.Bus(interface="zenoh", channel=f"senders-{time.monotonic_ns()}")
    try:
        frame = Frame(0x123, b"\x01")
        for sender in range(1, 3 * MAX_SENDERS):
            bus._on_message(Message(bus._channel, sender, 1, time.time(), Echo(), [frame]),
                            time.time(), time.monotonic())
        assert len(bus.heard()) <= MAX_SENDERS and len(bus._account._quickest) <= MAX_SENDERS
    finally:
        bus.shutdown()


def test_a_servers_results_are_bounded(monkeypatch):
    from hil.messaging import action

    class Publisher:
        def put(self, payload):
            pass

    server = action.TrajectoryActionServer.__new__(action.TrajectoryActionServer)
    server._results, server._result = {}, Publisher()
    server._lock = __import__("threading").Lock()
    monkeypatch.setattr(action, "KEPT_RESULTS", 10)
    result = GoalResult(GoalStatus.SUCCEEDED, 0, "")
    server.publish_results([(f"{n:032x}", result) for n in range(25)])
    assert list(server._results) == [f"{n:032x}" for n in range(15, 25)]


def test_a_goal_the_controller_fails_on_still_gets_an_answer(monkeypatch):
    """A defect in the controller's goal handling answers the client at once (rejected, with
    the error), where it used to log a traceback and leave it 'no controller answered'."""
    from hil.messaging import action

    class Query:
        payload, key_expr = None, "k"

        def __init__(self):
            self.answers = []

        def reply_err(self, text):
            self.answers.append(text)

    def fails(*_):
        raise AttributeError("'NoneType' object has no attribute 'copy'")

    server = action.TrajectoryActionServer.__new__(action.TrajectoryActionServer)
    server.controller, server.clock = None, time.monotonic
    monkeypatch.setattr(action, "submit_goal_request", fails)
    query = Query()
    server._on_send_goal(query)
    assert query.answers and query.answers[0].startswith("rejected (-1): the controller failed")


@pytest.mark.parametrize("setting, value, field", [
    ("heartbeat_period", "100", "0x1017"),             # UNSIGNED16 ms: 65.535 s at most
    ("watchdog_timeout", "70", "0x2010"),
    ("encoder_counts_per_rev", str(2**32), "0x608F:01"),
])
def test_hil_check_refuses_a_setting_the_drives_object_cannot_hold(tmp_path, setting, value,
                                                                   field):
    """What hil check accepts, hil sim can encode: a CiA 402 drive keeps these settings in
    objects of its EDS, whose types bound them."""
    config = tmp_path / "ur3.yaml"
    shipped = (Path(__file__).parents[1] / "bus_config" / "ur3.yaml").read_text()
    config.write_text(re.sub(rf"{setting}: [0-9.]+", f"{setting}: {value}", shipped)
                      .replace("../robots/", f"{Path(__file__).parents[1]}/robots/"))
    with pytest.raises(HilError, match=f"'{setting}' {value} does not fit the drive's {field}"):
        load_bus_config(config)


def test_a_flood_of_malformed_payloads_is_a_count_and_a_few_lines():
    """100,000 malformed stall reports used to be 100,000 log lines (issue 43)."""
    from hil.messaging.zenoh_api import MalformedPayloads

    lines: list[str] = []
    malformed = MalformedPayloads(lines.append)
    for _ in range(5000):
        malformed("hil/ur3/stalls", ValueError("not a hil_msgs/Stall"))
    assert malformed.count == 5000
    assert len(lines) == 5 and "(4001 so far)" in lines[-1] and "hil/ur3/stalls" in lines[0]


def _chain(joints: int) -> str:
    link = ('<link name="l{}"><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" '
            'izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>')
    joint = ('<joint name="j{0}" type="revolute"><parent link="l{0}"/><child link="l{1}"/>'
             '<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint>')
    return ('<robot name="chain">' + "".join(link.format(i) for i in range(joints + 1))
            + "".join(joint.format(i, i + 1) for i in range(joints)) + "</robot>")


@pytest.mark.parametrize("name, text, said", [
    ("chain.urdf", _chain(1000), "more than 200 joints deep"),
    ("macro.xacro", '<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro">'
                    '<xacro:macro name="m"><xacro:m/></xacro:macro><xacro:m/></robot>',
     "nests without end"),
    ("self.xacro", '<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro">'
                   '<xacro:include filename="self.xacro"/></robot>', "nests without end"),
])
def test_a_description_without_end_is_an_error_not_a_traceback(tmp_path, name, text, said):
    description = tmp_path / name
    description.write_text(text)
    with pytest.raises(HilError, match=said):
        load_description(description, PackagePath(()))


def test_a_mesh_path_the_system_cannot_take_is_a_missing_mesh(tmp_path):
    description = tmp_path / "long.urdf"
    description.write_text(_chain(1).replace(
        '<link name="l0">', f'<link name="l0"><visual><geometry><mesh filename="{"x" * 300}'
                            '.stl"/></geometry></visual>'))
    robot = load_description(description, PackagePath(()))
    assert any("not found" in warning.message for warning in robot.warnings)


# --- issue 65: hostile input, round two -----------------------------------------------------

def test_a_zenoh_config_nested_50000_deep_is_an_error_not_a_sigsegv(tmp_path):
    """Zenoh's JSON5 parser recurses: 50,000 levels overflowed the stack of `hil ls` and
    `hil sim` (SIGSEGV). The bounded reader counts the levels first."""
    config = tmp_path / "zenoh.json5"
    config.write_text('{"a": ' * 50_000 + "1" + "}" * 50_000)
    run = subprocess.run([sys.executable, "-m", "hil", "ls", "--zenoh-config", str(config),
                          "--timeout", "1s"], capture_output=True, text=True, timeout=120)
    assert run.returncode == 1, (run.returncode, run.stderr[-2000:])
    assert "zenoh.json5:1: error: Zenoh config is nested more than 100 deep" in run.stderr


@pytest.mark.timeout(60)
@pytest.mark.parametrize("make", [lambda path: os.mkfifo(path) or path,
                                  lambda _: Path("/dev/zero")])
def test_a_zenoh_config_that_is_a_fifo_or_a_device_is_refused(tmp_path, make):
    config = make(tmp_path / "zenoh.json5")     # Zenoh waited on the FIFO, read /dev/zero on
    with pytest.raises(HilError, match="Zenoh config .* is not a regular file"):
        ZenohSettings(config_file=config).to_config()


def test_a_zenoh_config_file_is_still_read_as_json5_or_yaml(tmp_path):
    json5 = tmp_path / "zenoh.json5"
    json5.write_text('{mode: "client", // JSON5: comments and bare keys\n}')
    yaml_file = tmp_path / "zenoh.yaml"
    yaml_file.write_text("mode: client\n")
    for config in (json5, yaml_file):
        assert ZenohSettings(config_file=config).to_config().get_json("mode") == '"client"'


@pytest.mark.parametrize("option", ["99999999999999999999s", "9000h", "525601min"])
def test_an_absurd_duration_is_refused_with_a_clear_message(option, capsys):
    """`hil ls --timeout 99999999999999999999s` reached Zenoh's get as "negative timeout"
    (a ValueError traceback); every duration option reads through hil.durations."""
    with pytest.raises(SystemExit) as exited:
        main(["ls", "--timeout", option])
    assert exited.value.code == 2
    assert "--timeout" in capsys.readouterr().err


def test_the_longest_duration_is_a_year():
    assert parse_duration("8760h") == 365 * 24 * 3600.0
    with pytest.raises(ValueError, match="longer than a year"):
        parse_duration("8761h")


def _scene_config(folder: Path, scene: str, extra: str = "") -> Path:
    """The one-axis Damiao config in ``folder`` with ``scene`` (YAML list items)."""
    config = _damiao_config(folder, "defaults:", f"{extra}defaults:")
    config.write_text(config.read_text() + "scene:\n" + scene)
    return config


def test_a_scene_of_more_than_64_objects_is_refused(tmp_path):
    """2000 cubes placed inside each other took 6 GB and 23 s to build the plant in
    `hil check`; 100 overran MuJoCo's arena (FatalError traceback)."""
    items = "".join(f"  - {{name: c{n}, shape: box, size: [0.1, 0.1, 0.1], mass: 0.1}}\n"
                    for n in range(65))
    with pytest.raises(HilError, match="'scene' holds 65 objects, over the 64 hil builds"):
        load_bus_config(_scene_config(tmp_path, items))


@pytest.mark.parametrize("entry, said", [
    ("{name: c, shape: box, size: [1.0e+300, 1, 1], mass: 1}", "at most 100"),
    ("{name: c, shape: mesh, mesh: m.stl, size: [1000, 1, 1]}", "at most 100"),
    ("{name: c, shape: sphere, size: [0.1], xyz: [0, 0, 1.0e+30]}", "each within ±100"),
])
def test_a_scene_objects_size_and_place_are_bounded(tmp_path, entry, said):
    (tmp_path / "m.stl").write_bytes(b"\0" * 84)
    with pytest.raises(HilError, match=said):
        load_bus_config(_scene_config(tmp_path, f"  - {entry}\n"))


@pytest.mark.parametrize("name", ["world", "base", "yaw"])
def test_a_scene_object_named_as_the_robots_link_or_joint_is_refused(tmp_path, name):
    """A scene object's name is no link's or joint's, nor MuJoCo's world's (hil's choice: a
    name in hil's messages names one thing; such a name was a ValueError traceback,
    "repeated name 'base' in body", before the plant put the scene in a namespace of its
    own, hil/plant/shapes.py)."""
    config = _scene_config(tmp_path, f"  - {{name: {name}, shape: box, size: [0.1, 0.1, 0.1]}}\n")
    with pytest.raises(HilError, match=f"scene object '{name}': the robot's model has a link"):
        load_bus_config(config)


@pytest.mark.parametrize("base", ["[fixed]", "{floating: true}"])
def test_a_base_that_is_no_word_is_an_error_not_a_traceback(tmp_path, base):
    config = _damiao_config(tmp_path, "defaults:", f"base: {base}\ndefaults:")
    with pytest.raises(HilError, match="'base' must be fixed or floating"):
        load_bus_config(config)


def test_a_yaml_escape_of_half_a_character_is_an_error_not_a_traceback(tmp_path):
    """YAML's "\\ud800" escape (YAML 1.2, 5.7: 16-bit escapes) gives PyYAML a lone UTF-16
    surrogate, no character at all: as a scene object's name MuJoCo's add_body raised a
    TypeError traceback (found by test_any_scene_gives_a_plant_or_a_config_error)."""
    config = _scene_config(tmp_path, '  - {name: "\\ud800\\udc00", shape: box, '
                                     'size: [0.1, 0.1, 0.1]}\n')
    with pytest.raises(HilError, match="surrogate"):
        bench_plant(load_bus_config(config))                # as hil check builds it


@pytest.mark.timeout(60)
def test_a_folder_or_fifo_beside_a_description_is_no_file_to_search(tmp_path):
    """Where a joint names a link no file defines, hil looks for the .xacro/.urdf beside the
    description that does: a folder named like one was read (IsADirectoryError traceback),
    a FIFO waited for a writer without end."""
    description = tmp_path / "robot.urdf"
    description.write_text(_chain(1).replace('<child link="l1"/>', '<child link="gone"/>'))
    (tmp_path / "arm.xacro").mkdir()
    os.mkfifo(tmp_path / "gripper.urdf")
    with pytest.raises(HilError, match="gone"):
        load_description(description, PackagePath(()))


@pytest.mark.parametrize("mesh, said", [
    ("x" * 300 + ".stl", "has a name of 304 bytes, over the 255"),   # was an OSError traceback
    ("/dev/zero", "is not a regular file"),
])
def test_a_scene_mesh_the_system_cannot_take_is_named(tmp_path, mesh, said):
    config = _scene_config(tmp_path, f"  - {{name: c, shape: mesh, mesh: {mesh}}}\n")
    with pytest.raises(HilError, match=f"mesh file .* {said}"):
        load_bus_config(config)
