"""Every input surface bounded (issue 43): a YAML alias bomb, a config nested without end,
a FIFO or a device named as a file, a flood of made-up Zenoh senders, goals without end:
each answered with a clear error or a bounded memory, never a hang or a traceback."""

from __future__ import annotations

import os
import re
import shutil
import time
from pathlib import Path

import can
import pytest

from hil.bus_config import load_bus_config
from hil.description import PackagePath, load_description
from hil.can.zenoh_bus import MAX_SENDERS
from hil.can.zenoh_wire import Echo, Message
from hil.controllers import GoalResult, GoalStatus
from hil.errors import HilError
from hil.input_files import read_input_file
from hil.protocols.odrive import ODriveOptions


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
        frame = (0x123, b"\x01")
        for sender in range(1, 3 * MAX_SENDERS):
            bus._on_message(Message(bus._channel, sender, 1, time.time(), Echo(), [frame], True),
                            time.time(), time.monotonic())
        assert len(bus.heard()) <= MAX_SENDERS and len(bus._quickest) <= MAX_SENDERS
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
