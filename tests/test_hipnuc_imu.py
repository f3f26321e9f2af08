"""A HiPNUC IMU in its CANopen mode on a bus of the bench: its TPDOs read by a CANopen master
(python canopen) through hil's EDS of it, as the maker's parser lays them out; counted in the
bus' load and ids; read and published by hil's controller."""

from __future__ import annotations

import math
import threading
from pathlib import Path

import can
import canopen
import numpy as np
import pytest
import yaml
from conftest import imu_messages, sensor_frames_a_second, wait_until

from hil.bus_config import load_bus_config
from hil.errors import ConfigError
from hil.protocols import hipnuc
from hil.protocols.imu import ImuSample, quaternion_of
from hil.realtime.timing import REAL_TIME
from hil.resources import hipnuc_eds_path
from hil.simulator import Simulator

FIXTURES = Path(__file__).parent / "fixtures"
ALL = tuple(hipnuc.OUTPUTS.values())


def _config(folder: Path, **sensor) -> Path:
    """tests/fixtures/ur3_virtual.yaml with a HiPNUC IMU as node 8 on its bus 'arm'
    (``sensor``'s keys over those), written into ``folder``."""
    config = yaml.safe_load((FIXTURES / "ur3_virtual.yaml").read_text())
    config["robot"] = str((FIXTURES / config["robot"]).resolve())
    config["sensors"] = [{"name": "imu", "product": "hipnuc", "link": "base_link",
                          "bus": "arm", "node_id": 8, "rate_hz": 100, **sensor}]
    path = folder / "ur3_hipnuc.yaml"
    path.write_text(yaml.safe_dump(config, sort_keys=False))
    return path


def test_the_frames_are_the_makers_layout_to_the_count():
    sample = ImuSample(np.array([0.0981, -0.1962, 9.81]), np.array([math.radians(12.3), 0, 0]),
                       quaternion_of(math.radians(1.5), 0.0, 0.0))
    frames = {f.identifier: f.data for f in hipnuc.frames(sample, 8, ALL)}
    # canopen_parser.c: int16 little endian, 0.001 g (9.81), 0.1 deg/s, 0.01 deg, 0.0001
    assert np.frombuffer(frames[0x188], "<i2").tolist() == [10, -20, 1000]
    assert np.frombuffer(frames[0x288], "<i2").tolist() == [123, 0, 0]
    assert np.frombuffer(frames[0x388], "<i2").tolist() == [150, 0, 0]
    assert len(frames[0x488]) == 8 and np.frombuffer(frames[0x488], "<i2")[0] == 9999


@pytest.fixture
def master_bus():
    """A bench's in-process bus 'arm' with its simulator running, and a CANopen master's end
    of it."""
    channel = f"hil_test_hipnuc_{id(object())}"
    sim_end, master_end = (can.Bus(interface="virtual", channel=channel) for _ in range(2))
    yield sim_end, master_end
    sim_end.shutdown()
    master_end.shutdown()


def test_a_canopen_master_reads_the_tpdos_through_the_eds(tmp_path, master_bus):
    sim_end, master_end = master_bus
    network = canopen.Network(master_end)
    network.notifier = can.Notifier(master_end, network.listeners, 0.1)
    node = canopen.RemoteNode(8, str(hipnuc_eds_path()))
    network.add_node(node)
    node.tpdo.read(from_od=True)
    sim = Simulator(load_bus_config(_config(tmp_path)), {"arm": sim_end}, REAL_TIME)
    runner = threading.Thread(target=sim.run, daemon=True)
    sim.start()
    runner.start()
    try:
        assert node.tpdo[1].wait_for_reception(5) and node.tpdo[4].wait_for_reception(5)
        acceleration = [node.tpdo[1][f"Acceleration.{axis}"].raw * 0.001 * 9.81
                        for axis in "XYZ"]
        quaternion = [node.tpdo[4][f"Quaternion.{part}"].raw * 1e-4 for part in "WXYZ"]
        angles = [node.tpdo[3][f"Euler angles.{part}"].raw for part in ("Roll", "Pitch")]
    finally:
        sim.stop()
        runner.join(5)
        sim.close()
        network.notifier.stop()
    assert acceleration == pytest.approx([0, 0, 9.81], abs=0.05)      # a still base: +g up
    assert quaternion == pytest.approx([1, 0, 0, 0], abs=2e-4) and angles == [0, 0]


def test_nmt_stop_silences_the_imu_and_start_brings_it_back(tmp_path, master_bus):
    sim_end, master_end = master_bus
    sim = Simulator(load_bus_config(_config(tmp_path, rate_hz=50)), {"arm": sim_end}, REAL_TIME)
    runner = threading.Thread(target=sim.run, daemon=True)
    sim.start()
    runner.start()
    port = sim.sensor("imu").port
    try:
        boots = [master_end.recv(5) for _ in range(7)]       # six drives' and the IMU's
        assert [bytes(m.data) for m in boots if m.arbitration_id == 0x708] == [b"\x00"]
        master_end.send(can.Message(arbitration_id=0, data=[0x02, 8], is_extended_id=False))
        wait_until(lambda: not port.operational)
        lost = port.lost_frames
        wait_until(lambda: port.lost_frames > lost)                 # samples taken, not sent
        master_end.send(can.Message(arbitration_id=0, data=[0x01, 0], is_extended_id=False))
        wait_until(lambda: port.operational)
    finally:
        sim.stop()
        runner.join(5)
        sim.close()


def test_the_imu_counts_in_its_bus_load_and_its_ids(tmp_path):
    assert sensor_frames_a_second(_config(tmp_path)) == pytest.approx(400)
    with pytest.raises(ConfigError, match=r"CAN id 0x183 is used by sensor 'imu' TPDO1 and "
                                          r"by node 3"):
        load_bus_config(_config(tmp_path, node_id=3))


@pytest.mark.parametrize("sensor, message", [
    ({"bus": "nowhere"}, "the config has no bus 'nowhere'"),
    ({"port": "/tmp/x"}, "'port' is not for a hipnuc sensor"),
    ({"node_id": 200}, "'node_id' is 1 to 127"),
    ({"rate_hz": 400}, "'rate_hz' 400 is none the product offers"),
])
def test_a_bad_can_sensor_entry_is_refused_naming_the_sensor_and_its_line(tmp_path, sensor,
                                                                          message):
    with pytest.raises(ConfigError) as refused:
        load_bus_config(_config(tmp_path, **sensor))
    assert message in str(refused.value) and "ur3_hipnuc.yaml:" in str(refused.value)


def test_the_controller_publishes_the_imu_it_reads_off_the_bus(tmp_path):
    last = imu_messages(load_bus_config(_config(tmp_path, link="link6")), 10)[-1]
    assert last.header.frame_id == "link6"
    acceleration = np.array([last.linear_acceleration.x, last.linear_acceleration.y,
                             last.linear_acceleration.z])
    assert np.linalg.norm(acceleration) == pytest.approx(9.81, abs=0.15)
