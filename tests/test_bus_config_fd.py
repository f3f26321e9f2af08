"""A bus config's CAN FD: a bus declares ``fd`` and its data phase's bit rate; an FD-only
device needs an FD bus, a classical-only one cannot share a bus with FD frames (CiA's CAN FD
guidance: a classical controller that is not FD-tolerant destroys them with error frames);
the bus load counts both phases (ISO 11898-1:2015); a stray FD frame on a classical bus moves
no motor and is reported naming the bus and the node."""

from __future__ import annotations

import logging

import pytest

from hil.bus_config import load_bus_config
from hil.can.frame import Frame
from hil.can.frames import bus_load
from hil.can.router import FrameRouter
from hil.cli import main
from hil.errors import HilError
from conftest import TESTS

ROBOT = TESTS / "fixtures" / "damiao_one_axis.urdf"


def config(tmp_path, bus_keys: str, drives: str = "- {node_id: 1, joint: yaw}"):
    path = tmp_path / "fd.yaml"
    lines = "".join(f"      {line}\n" for line in drives.splitlines())
    path.write_text(f"""\
robot: {ROBOT}
transmissions:
  yaw: {{reduction: 1, rotor_inertia: 0.0018}}
buses:
  - name: axis
    interface: hil-virtual
    channel: fd-test
    cycle_hz: 100
{bus_keys}
    drives:
{lines}""")
    return path


def problems(path) -> list[str]:
    with pytest.raises(HilError) as caught:
        load_bus_config(path)
    return [f"{d.message} (line {d.line})" for d in caught.value.diagnostics]


def test_an_fd_bus_has_a_data_phase_of_5_mbit_s_unless_it_names_one(tmp_path):
    bus = load_bus_config(config(tmp_path, "    fd: true")).buses[0]
    assert (bus.fd, bus.bitrate, bus.data_bitrate) == (True, 1_000_000, 5_000_000)
    assert bus.drives[0].can_fd
    named = load_bus_config(config(tmp_path, "    fd: true\n    data_bitrate: 2000000"))
    assert named.buses[0].data_bitrate == 2_000_000
    classical = load_bus_config(config(tmp_path, "")).buses[0]
    assert (classical.fd, classical.data_bitrate, classical.drives[0].can_fd) == (
        False, None, False)


@pytest.mark.parametrize("keys, said", [
    ("    data_bitrate: 5000000", "data_bitrate is the data phase of CAN FD frames; this bus "
                                  "is classical (line 9)"),
    ("    fd: true\n    data_bitrate: 500000", "data_bitrate 500000 is below bitrate 1000000 "
                                               "(line 10)"),
    ("    fd: yes please", "fd must be true or false (line 9)"),
])
def test_a_wrong_fd_setting_is_refused_naming_its_line(tmp_path, keys, said):
    assert any(said in problem for problem in problems(config(tmp_path, keys)))


def test_an_fd_only_device_on_a_classical_bus_is_refused_naming_bus_and_node(
        tmp_path, toy_installed):
    said = problems(config(tmp_path, "", "- {node_id: 1, joint: yaw, protocol: toy}"))
    assert any("bus 'axis': node 1 (yaw) speaks CAN FD only (toy), on a classical bus" in p
               for p in said)


def test_a_classical_device_cannot_share_an_fd_bus_with_fd_frames(tmp_path, toy_installed):
    two = config(tmp_path, "    fd: true", "- {node_id: 1, joint: yaw, protocol: toy}\n"
                                           "- {node_id: 2, joint: yaw, protocol: cia402}")
    said = problems(two)
    assert any("bus 'axis': node 2 (yaw) is a classical CAN device (cia402) on an FD bus "
               "whose toy drives exchange FD frames" in p for p in said)


def test_a_classical_device_alone_on_an_fd_bus_is_fine(tmp_path):
    assert load_bus_config(config(tmp_path, "    fd: true")).buses[0].fd


def test_the_load_of_an_fd_bus_counts_its_data_phase_at_the_data_bit_rate(
        tmp_path, toy_installed, capsys):
    path = config(tmp_path, "    fd: true\n    data_bitrate: 4000000",
                  "- {node_id: 1, joint: yaw, protocol: toy}")
    bus = load_bus_config(path).buses[0]
    specs = [spec for spec in bus.frames(bus.drives[0]) if spec.rate > 0]
    assert specs and all(spec.fd and spec.bitrate_switch for spec in specs)
    assert bus.load() == bus_load(1_000_000, specs, 4_000_000)
    slower = bus_load(1_000_000, specs)               # no switch: the whole frame at 1 Mbit/s
    assert bus.load().worst_bits_per_second < slower.worst_bits_per_second
    assert main(["check", str(path)]) == 0
    assert "1,000 kbit/s CAN FD, 4,000 kbit/s data" in capsys.readouterr().out


def test_an_fd_frame_on_a_classical_bus_reaches_no_device_and_is_reported(tmp_path, caplog):
    bus = load_bus_config(config(tmp_path, "")).buses[0]       # node 1: cia402
    rpdo1 = Frame(0x201, bytes(8), fd=True, bitrate_switch=True)
    assert bus.frame_owner(rpdo1) == "node 1, RPDO1"
    router = FrameRouter(bus=None, classical=bus.name, describe=bus.frame_owner)
    taken: list[Frame] = []
    router.subscribe(0x201, taken.append)
    with caplog.at_level(logging.WARNING, logger="hil.can.router"):
        router.on_frames([rpdo1, rpdo1._replace(fd=False, bitrate_switch=False)])
    assert taken == [rpdo1._replace(fd=False, bitrate_switch=False)]
    assert router.fd_on_classical == 1
    assert "bus 'axis': CAN FD frame" in caplog.text and "(node 1, RPDO1)" in caplog.text


def test_describe_tells_an_fd_bus_its_data_rate_its_fd_frames_and_how_to_join_it(
        tmp_path, toy_installed, capsys):
    path = config(tmp_path, "    fd: true", "- {node_id: 1, joint: yaw, protocol: toy}")
    assert main(["describe", str(path)]) == 0
    said = capsys.readouterr().out
    assert "1,000 kbit/s CAN FD, 5,000 kbit/s data" in said
    assert 'can.Bus(interface="hil-virtual", channel="fd-test", fd=True)' in said
    assert "(CAN FD, BRS)" in said
