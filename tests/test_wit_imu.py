"""A WitMotion IMU on a link of the robot, on a pseudo-terminal, read by the published
``witmotion`` reader (pyserial) and checked by ``allantools`` (both from PyPI, pinned)."""

from __future__ import annotations

import math
import subprocess
import sys
import threading
import time
from pathlib import Path

import allantools
import can
import numpy as np
import pytest
import serial
import yaml
from witmotion import IMU, protocol

from hil.bus_config import load_bus_config
from hil.can.faults import SensorFaultKind
from hil.errors import ConfigError
from hil.protocols import wit
from hil.protocols.imu import ImuSample
from hil.realtime.timing import LOCK_STEP, REAL_TIME
from hil.sensors.imu import SimulatedImu
from hil.sensors.noise import ALLAN_FLOOR, GAUSS_MARKOV_PEAK
from hil.sensors.port import Port
from hil.sensors.serial_port import PseudoTerminal
from hil.simulator import Simulator
from hil.simulator.build import bench_plant
from hil.simulator.stepping import PlantStepping
from hil.stack import Stack

FIXTURES = Path(__file__).parent / "fixtures"


def _config(folder: Path, **sensor) -> Path:
    """tests/fixtures/ur3_virtual.yaml with one WIT IMU (``sensor``'s keys over the defaults),
    written into ``folder``."""
    config = yaml.safe_load((FIXTURES / "ur3_virtual.yaml").read_text())
    config["robot"] = str((FIXTURES / config["robot"]).resolve())
    config["sensors"] = [{"name": "imu", "product": "wit", "link": "base_link",
                          "port": str(folder / "imu"), "baud": 460800, "rate_hz": 200,
                          **sensor}]
    path = folder / "ur3_imu.yaml"
    path.write_text(yaml.safe_dump(config, sort_keys=False))
    return path


class Capture(Port[bytes]):
    """A port that keeps what is written to it."""

    device = "a test's capture"

    def __init__(self):
        self.data = bytearray()

    def write(self, data: bytes) -> None:
        self.data += data


def _imu(config, plant, port) -> SimulatedImu:
    """The config's first IMU, a WitMotion one, on ``port``."""
    imu = config.sensors[0]
    return SimulatedImu(imu, lambda: plant.sensors.read(imu.name), port)


def _parsed(data: bytes) -> dict[int, list]:
    """The witmotion reader's messages in ``data``, by packet type, every checksum checked."""
    found: dict[int, list] = {}
    assert len(data) % wit.PACKET_BYTES == 0
    for start in range(0, len(data), wit.PACKET_BYTES):
        packet = data[start:start + wit.PACKET_BYTES]
        assert packet[0] == 0x55
        kind = protocol.receive_messages[packet[1]]
        assert kind.compute_checksum(packet[2:10]) == packet[10]
        found.setdefault(packet[1], []).append(kind.parse(packet[2:10]))
    return found


def test_a_sample_is_what_the_witmotion_reader_parses_within_a_step_of_each_field():
    orientation = np.array([math.cos(0.2), math.sin(0.2), 0.0, 0.0])     # 0.4 rad of roll
    sample = ImuSample(np.array([0.5, -1.25, 9.81]), np.array([0.1, -2.0, 0.0]),
                           orientation)
    messages = _parsed(wit.encode(sample, tuple(wit.OUTPUTS.values())))
    a = messages[wit.ACCELERATION][0]
    assert np.allclose(a.a, sample.acceleration, atol=16 * wit.G / 32768)
    assert a.temp_celsius == wit.TEMPERATURE
    w = messages[wit.ANGULAR_VELOCITY][0]
    assert np.allclose(np.radians(w.w), sample.angular_velocity, atol=math.radians(2000 / 32768))
    angle = messages[wit.ANGLE][0]
    assert (angle.roll, angle.pitch, angle.yaw) == pytest.approx(
        (math.degrees(0.4), 0.0, 0.0), abs=180 / 32768)
    assert messages[wit.QUATERNION][0].q == pytest.approx(tuple(orientation), abs=1 / 32768)


def test_a_reading_past_the_range_saturates_at_the_range():
    sample = ImuSample(np.array([1e3, -1e3, 0.0]), np.array([100.0, 0.0, -100.0]),
                           np.array([1.0, 0.0, 0.0, 0.0]))
    messages = _parsed(wit.encode(sample, (wit.ACCELERATION, wit.ANGULAR_VELOCITY)))
    assert messages[wit.ACCELERATION][0].a[:2] == pytest.approx((16 * wit.G, -16 * wit.G),
                                                                rel=1e-4)
    assert messages[wit.ANGULAR_VELOCITY][0].w[0] == pytest.approx(2000, rel=1e-4)


def _still_record(config_path: Path, seconds: float) -> tuple[dict[int, list], object]:
    """``seconds`` of plant time of the config's still robot (its base's IMU), stepped as the
    simulator steps it, the IMU's bytes captured; the plant too."""
    config = load_bus_config(config_path)
    plant = bench_plant(config)
    stepping = PlantStepping(plant)
    capture = Capture()
    stepping.sensors.append(_imu(config, plant, capture))
    for _ in range(round(seconds * config.plant_rate_hz)):
        stepping.step()
    return _parsed(bytes(capture.data)), plant


def _fitted(series: np.ndarray, rate: float, correlation: float) -> tuple[float, float]:
    """The noise density and bias instability fitted to ``series``' overlapping Allan
    deviation (allantools): its variance as N²/τ plus the Gauss-Markov bias' curve, by least
    squares relative to each point."""
    taus, deviation, _, _ = allantools.oadev(series, rate=rate, data_type="freq",
                                             taus=np.logspace(-1.3, math.log10(10 * correlation),
                                                              24))
    x = taus / correlation
    markov = 2 / x * (1 - (3 - 4 * np.exp(-x) + np.exp(-2 * x)) / (2 * x))   # unit σ
    per_b2 = markov * (ALLAN_FLOOR / GAUSS_MARKOV_PEAK) ** 2
    design = np.stack([1 / taus, per_b2], axis=1) / deviation[:, None] ** 2
    (n2, b2), *_ = np.linalg.lstsq(design, np.ones_like(taus), rcond=None)
    return math.sqrt(n2), math.sqrt(b2)


def test_a_still_imu_recorded_ten_minutes_has_the_configured_allan_deviation(tmp_path):
    # lock-step: plant time, stepped as fast as it goes. A density and an instability whose
    # Allan curves cross near 0.3 s, so that ten minutes hold over a thousand of the bias'
    # correlation times and the fit's scatter is a third of the tolerance (3 % over 8 seeds
    # and 24 series); a real MEMS part's floor lies at 100-1000 s and takes hours to measure
    gyro = {"noise_density": 1e-3, "bias_instability": 2e-3, "correlation_time": 0.5}
    accel = {"noise_density": 2e-3, "bias_instability": 4e-3, "correlation_time": 0.5}
    path = _config(tmp_path, gyroscope=gyro, accelerometer=accel, seed=7)
    # the plant at 200 Hz: one IMU sample a step, ten minutes in seconds of CPU
    raw = yaml.safe_load(path.read_text())
    raw["plant_rate_hz"] = 200
    path.write_text(yaml.safe_dump(raw))
    messages, plant = _still_record(path, 600.0)
    rates = np.radians([m.w for m in messages[wit.ANGULAR_VELOCITY]])
    forces = np.array([m.a for m in messages[wit.ACCELERATION]])
    assert len(rates) == len(forces) == 600 * 200
    for series, errors in ((rates, gyro), (forces, accel)):
        for axis in range(3):
            density, instability = _fitted(series[:, axis], 200.0, errors["correlation_time"])
            assert density == pytest.approx(errors["noise_density"], rel=0.1), axis
            assert instability == pytest.approx(errors["bias_instability"], rel=0.1), axis
    # gravity in the sensor's axes: +g up on a still base, its mean within the bias' spread
    assert forces.mean(axis=0) == pytest.approx([0, 0, 9.81], abs=0.02)
    # the orientation is the plant's (hil runs no fusion filter), within a step of the field
    angles = messages[wit.ANGLE][-1]
    assert (angles.roll, angles.pitch, angles.yaw) == pytest.approx((0, 0, 0), abs=180 / 32768)


def test_the_same_seed_gives_the_same_bytes_and_another_seed_others(tmp_path):
    runs = {}
    for seed in (1, 1, 2):
        folder = tmp_path / f"run{len(runs)}"
        folder.mkdir()
        runs[len(runs)] = _still_record(_config(folder, seed=seed), 0.5)[0]
    assert _same(runs[0], runs[1]) and not _same(runs[0], runs[2])


def _same(a: dict[int, list], b: dict[int, list]) -> bool:
    return all([vars(m) for m in a[k]] == [vars(m) for m in b[k]] for k in a)


@pytest.fixture
def virtual_bus():
    """An in-process bus of the test's own, shut down after it."""
    bus = can.Bus(interface="virtual", channel=f"hil_test_wit_{id(object())}")
    yield bus
    bus.shutdown()


def test_the_witmotion_reader_opens_the_port_and_reads_gravity_from_a_running_simulator(
        tmp_path, virtual_bus):
    config = load_bus_config(_config(tmp_path, rate_hz=50))
    sim = Simulator(config, {"arm": virtual_bus}, REAL_TIME)
    runner = threading.Thread(target=sim.run, daemon=True)
    sim.start()
    runner.start()
    imu = IMU(str(tmp_path / "imu"), baudrate=460800)
    try:
        deadline = time.monotonic() + 10
        while (imu.last_a is None or imu.last_roll is None) and time.monotonic() < deadline:
            time.sleep(0.02)
        assert imu.last_a == pytest.approx((0, 0, 9.81), abs=0.1)
        assert (imu.last_roll, imu.last_pitch) == pytest.approx((0, 0), abs=0.01)
    finally:
        imu.close()
        sim.stop()
        runner.join(5)
        sim.close()
    assert not (tmp_path / "imu").is_symlink()        # the port's link went with the run
    assert sim.sensors[0].sent > 0


def test_samples_sent_while_no_reader_has_the_port_open_are_lost_not_kept(tmp_path):
    port = PseudoTerminal(tmp_path / "imu")
    try:
        port.write(b"stale")
        assert port.lost_bytes == 5
        with serial.Serial(str(tmp_path / "imu"), 460800, timeout=0.2) as reader:
            port.write(b"fresh")
            assert reader.read(10) == b"fresh"
    finally:
        port.close()
    assert not (tmp_path / "imu").exists()


@pytest.mark.parametrize("sensor, message", [
    ({"link": "no_such_link"}, "the robot has no link 'no_such_link'"),
    ({"baud": 9600}, "take 66,000 bit/s, more than 9600 baud carries"),
    ({"rate_hz": 300}, "'rate_hz' 300 is none the product offers"),
    ({"product": "vectornav"}, "unknown product 'vectornav'"),
    ({"outputs": ["angle", "magnetic"]}, "'outputs' is a list of"),
    ({"gyroscope": {"noise_density": -1}}, "'noise_density' must be >= 0"),
    ({"gyroscope": {"bias": [0, 0]}}, "'bias' must be three finite numbers"),
])
def test_a_bad_sensor_entry_is_refused_naming_the_sensor_and_its_line(tmp_path, sensor,
                                                                      message):
    with pytest.raises(ConfigError) as refused:
        load_bus_config(_config(tmp_path, **sensor))
    text = str(refused.value)
    assert message in text and "sensor 'imu'" in text and "ur3_imu.yaml:" in text, text


def test_a_port_path_taken_by_a_file_is_refused_before_anything_runs(tmp_path, virtual_bus):
    (tmp_path / "imu").write_text("mine")
    config = load_bus_config(_config(tmp_path))
    with pytest.raises(ConfigError, match="exists and is not a link"):
        Simulator(config, {"arm": virtual_bus}, REAL_TIME)
    assert (tmp_path / "imu").read_text() == "mine"


def test_every_sensors_block_of_the_docs_loads_as_it_stands(tmp_path):
    page = (Path(__file__).parents[1] / "docs" / "sensors.md").read_text()
    blocks = [b.split("```")[0] for b in page.split("```yaml\n")[1:] if b.startswith("sensors:")]
    root = Path(__file__).parents[1] / "bus_config"
    loaded = []
    for number, block in enumerate(blocks):
        # the force-torque sensor's example is the pigot's wrist
        bench = "pigot_pick.yaml" if "ati_netft" in block else "ur3.yaml"
        config = yaml.safe_load((root / bench).read_text())
        config["robot"] = str((root / config["robot"]).resolve())
        config.update(yaml.safe_load(block))
        path = tmp_path / f"ur3_docs{number}.yaml"
        path.write_text(yaml.safe_dump(config))
        loaded += load_bus_config(path).sensors
    wit_imu, hipnuc_imu, dm_imu, netft = loaded
    assert (netft.link, netft.base_id, netft.short_divisors) == ("arm_link_6", 0x10,
                                                                 (1000.0, 100.0))
    assert (wit_imu.link, wit_imu.baud, wit_imu.rate_hz, wit_imu.port) == (
        "base_link", 460800, 200, Path("/tmp/hil-imu"))
    assert wit_imu.gyroscope.noise_density == pytest.approx(math.radians(0.01), rel=0.01)
    assert (hipnuc_imu.bus, hipnuc_imu.node_id, hipnuc_imu.rate_hz) == ("wrist", 8, 100)
    assert (dm_imu.node_id, dm_imu.master_id, dm_imu.firmware, dm_imu.poll_hz,
            dm_imu.rate_hz) == (1, 0x11, 1022, 100, 1000)



def _faulted_record(tmp_path: Path, kind: SensorFaultKind, at: float = 0.2
                    ) -> list[bytes]:
    """Half a second of the still IMU's samples at 50 Hz (each sample's bytes), ``kind``
    injected at ``at`` s of plant time."""
    config = load_bus_config(_config(tmp_path, rate_hz=50))
    plant = bench_plant(config)
    stepping = PlantStepping(plant)
    capture = Capture()
    imu = _imu(config, plant, capture)
    imu.inject(kind, at)
    stepping.sensors.append(imu)
    samples = []
    for _ in range(500):
        before = len(capture.data)
        stepping.step()
        if len(capture.data) > before:
            samples.append(bytes(capture.data[before:]))
    return samples


def test_a_silenced_imu_sends_nothing_from_its_moment_on(tmp_path):
    assert len(_faulted_record(tmp_path, SensorFaultKind.SILENCE)) == 9   # 20 ms ... 180 ms


def test_a_frozen_imu_repeats_one_sample_from_its_moment_on(tmp_path):
    samples = _faulted_record(tmp_path, SensorFaultKind.FREEZE)
    assert len(samples) == 25 and len(set(samples[9:])) == 1 and len(set(samples[:10])) == 10


def test_a_spike_is_one_sample_at_full_scale(tmp_path):
    samples = _faulted_record(tmp_path, SensorFaultKind.SPIKE)
    spiked = [i for i, sample in enumerate(samples)
              if _parsed(sample)[wit.ACCELERATION][0].a[0] > 15 * wit.G]
    assert spiked == [9]
    assert _parsed(samples[9])[wit.ANGULAR_VELOCITY][0].w == pytest.approx((2000,) * 3,
                                                                          rel=1e-3)


def test_hil_sim_refuses_a_fault_of_a_sensor_the_config_does_not_have(tmp_path):
    result = subprocess.run([sys.executable, "-m", "hil", "sim", str(_config(tmp_path)),
                             "--fault", "freeze:gyro@1", "--duration", "0.1"],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode != 0 and "--fault freeze:gyro@1: no sensor of that name" in result.stderr
    assert "sensors: imu" in result.stderr and "Traceback" not in result.stderr


def test_a_link_of_the_users_at_the_port_is_never_removed(tmp_path, virtual_bus):
    (tmp_path / "imu").symlink_to(tmp_path / "nowhere")            # dangling, not a terminal
    config = load_bus_config(_config(tmp_path))
    with pytest.raises(ConfigError, match="is taken: it links to"):
        Simulator(config, {"arm": virtual_bus}, REAL_TIME)
    assert (tmp_path / "imu").is_symlink()


def test_a_stack_whose_sensor_port_is_taken_says_so_and_leaves_no_bus_open(tmp_path,
                                                                            monkeypatch):
    """The simulator refuses the config (another run serves the port): the error names the
    port, and the buses the stack had opened are shut down, not left to the collector."""
    config = load_bus_config(_config(tmp_path))
    (tmp_path / "imu").symlink_to("/dev/null")          # taken: a link that is not stale
    opened, make = [], can.Bus

    def bus(**kwargs):
        opened.append(make(**kwargs))
        return opened[-1]

    monkeypatch.setattr(can, "Bus", bus)
    with pytest.raises(ConfigError, match="is taken"):
        Stack(config, LOCK_STEP)
    assert opened and all(each._is_shutdown for each in opened)
