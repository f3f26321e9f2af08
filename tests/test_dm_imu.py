"""Damiao's DM-IMU-L1 on a bus of the bench: read by a master written from the maker's
manual (V1.1, section 3 and appendices 2-3, transcribed below), in each firmware's request
form; counted in the bus' load and ids; polled, read and published by hil's controller."""

from __future__ import annotations

import math
import struct
import threading
import time
from pathlib import Path

import can
import numpy as np
import pytest
import yaml
from conftest import RecordingRouter, imu_messages, sensor_frames_a_second, wait_until

from hil.bus_config import load_bus_config
from hil.can.faults import SensorFaultKind
from hil.can.frame import Frame
from hil.errors import ConfigError
from hil.protocols import dm_imu
from hil.protocols.imu import ImuSample, quaternion_of
from hil.realtime.timing import REAL_TIME
from hil.sensors.polled_port import PolledImuPort
from hil.simulator import Simulator

FIXTURES = Path(__file__).parent / "fixtures"


def _config(folder: Path, **sensor) -> Path:
    """tests/fixtures/ur3_virtual.yaml at 1 Mbit/s (the IMU's only rate) with a DM-IMU on
    its bus 'arm' (``sensor``'s keys over the maker's example ids), written into
    ``folder``."""
    config = yaml.safe_load((FIXTURES / "ur3_virtual.yaml").read_text())
    config["robot"] = str((FIXTURES / config["robot"]).resolve())
    config["buses"][0]["bitrate"] = 1_000_000
    config["sensors"] = [{"name": "imu", "product": "dm_imu", "link": "base_link",
                          "bus": "arm", **sensor}]
    path = folder / "ur3_dm_imu.yaml"
    path.write_text(yaml.safe_dump(config, sort_keys=False))
    return path


# --- a master written from the manual (its appendices' C, transcribed) --------------------

ACCEL_CAN_MAX, GYRO_CAN_MAX = 58.8, 34.88
PITCH_CAN_MAX, YAW_CAN_MAX, ROLL_CAN_MAX = 90.0, 180.0, 180.0


def uint_to_float(x_int: int, x_min: float, x_max: float, bits: int) -> float:
    span = x_max - x_min
    return x_int * span / ((1 << bits) - 1) + x_min


def manual_request(can_id: int, reg: int) -> can.Message:
    """IMU_RequestData (appendix 3): StdId 0x6FF, DLC 4."""
    return can.Message(arbitration_id=0x6FF, is_extended_id=False,
                       data=[can_id & 0xFF, can_id >> 8, reg, 0xCC])


def manual_update(imu: dict, p: bytes, accel_max: float = ACCEL_CAN_MAX) -> None:
    """IMU_UpdateData and its four handlers (appendix 3), as printed: the quaternion's w
    takes (pData[2] & 0xF8) >> 2, which drops its lowest bit."""
    if p[0] == 1:
        imu["accel"] = [uint_to_float(p[3 + 2 * i] << 8 | p[2 + 2 * i], -accel_max, accel_max,
                                      16) for i in range(3)]
    elif p[0] == 2:
        imu["gyro"] = [uint_to_float(p[3 + 2 * i] << 8 | p[2 + 2 * i], -GYRO_CAN_MAX,
                                     GYRO_CAN_MAX, 16) for i in range(3)]
    elif p[0] == 3:
        imu["pitch"] = uint_to_float(p[3] << 8 | p[2], -PITCH_CAN_MAX, PITCH_CAN_MAX, 16)
        imu["yaw"] = uint_to_float(p[5] << 8 | p[4], -YAW_CAN_MAX, YAW_CAN_MAX, 16)
        imu["roll"] = uint_to_float(p[7] << 8 | p[6], -ROLL_CAN_MAX, ROLL_CAN_MAX, 16)
    elif p[0] == 4:
        w = p[1] << 6 | ((p[2] & 0xF8) >> 2)
        x = (p[2] & 0x03) << 12 | (p[3] << 4) | ((p[4] & 0xF0) >> 4)
        y = (p[4] & 0x0F) << 10 | (p[5] << 2) | (p[6] & 0xC0) >> 6
        z = (p[6] & 0x3F) << 8 | p[7]
        imu["q"] = [uint_to_float(v, -1.0, 1.0, 14) for v in (w, x, y, z)]


def test_the_answers_are_the_manuals_layout_to_the_count():
    roll, pitch, yaw = math.radians(10), math.radians(-20), math.radians(30)
    sample = ImuSample(np.array([0.5, -1.0, 9.81]), np.array([0.1, -0.2, 3.0]),
                       quaternion_of(roll, pitch, yaw))
    firmware = dm_imu.FIRMWARES[1022]
    imu: dict = {}
    for register in (1, 2, 3, 4):
        frame = dm_imu.answer(sample, register, 0x11, firmware)
        assert frame.identifier == 0x11 and len(frame.data) == 8 and frame.data[0] == register
        manual_update(imu, frame.data)
    step = 2 * ACCEL_CAN_MAX / 65535
    assert imu["accel"] == pytest.approx([0.5, -1.0, 9.81], abs=step)
    assert imu["gyro"] == pytest.approx([0.1, -0.2, 3.0], abs=2 * GYRO_CAN_MAX / 65535)
    assert [imu["roll"], imu["pitch"], imu["yaw"]] == pytest.approx([10, -20, 30], abs=0.01)
    # 14-bit parts; the manual's w loses its lowest bit: two steps
    assert imu["q"] == pytest.approx(quaternion_of(roll, pitch, yaw).tolist(), abs=2 * 2 / 16383)
    accel_answer = dm_imu.answer(sample, 1, 0x11, firmware).data
    assert accel_answer[1] == dm_imu.TEMPERATURE_C       # "温度", a true value, not mapped


def test_values_past_a_fields_range_saturate_at_its_end():
    sample = ImuSample(np.array([1e6, -1e6, 0.0]), np.array([1e6, -1e6, 0.0]),
                       np.array([1.0, 0, 0, 0]))
    for register in (1, 2):
        raw = struct.unpack_from("<3H", dm_imu.answer(sample, register, 0x11,
                                                      dm_imu.FIRMWARES[1022]).data, 2)
        assert raw[:2] == (65535, 0)
    # an infinite or undefined value answers too (NaN as a Cortex-M converts it: 0)
    odd = ImuSample(np.array([math.inf, -math.inf, math.nan]), np.zeros(3),
                    np.array([1.0, 0, 0, 0]))
    raw = struct.unpack_from("<3H", dm_imu.answer(odd, 1, 0x11, dm_imu.FIRMWARES[1022]).data, 2)
    assert raw == (65535, 0, 0)
    # firmware 1023 raised the range to ±24 g: the same field, a quarter of the resolution
    raw = struct.unpack_from("<3H", dm_imu.answer(
        ImuSample(np.array([100.0, 0, 0]), np.zeros(3), np.array([1.0, 0, 0, 0])), 1, 0x11,
        dm_imu.FIRMWARES[1023]).data, 2)
    assert uint_to_float(raw[0], -235.2, 235.2, 16) == pytest.approx(100.0, abs=0.01)


@pytest.fixture
def master_bus():
    """A bench's in-process bus 'arm' and a master's end of it."""
    channel = f"hil_test_dm_imu_{id(object())}"
    sim_end, master_end = (can.Bus(interface="virtual", channel=channel) for _ in range(2))
    yield sim_end, master_end
    sim_end.shutdown()
    master_end.shutdown()


def _running(path: Path, sim_end: can.BusABC):
    sim = Simulator(load_bus_config(path), {"arm": sim_end}, REAL_TIME)
    runner = threading.Thread(target=sim.run, daemon=True)
    sim.start()
    runner.start()
    return sim, runner


def _answers(master_end: can.BusABC, request: can.Message, answer_id: int,
             tries: int = 100) -> bytes | None:
    """The answer at ``answer_id`` to ``request``, resent every 0.1 s until one comes (the
    IMU answers from its first sample on); None if none comes (a second of silence where a
    test asks 10 tries). The drives' frames pass too, so a try ends by the clock: ended when
    the bus fell quiet, which it never does, a try read a thousand of them (17 s)."""
    for _ in range(tries):
        master_end.send(request)
        deadline = time.monotonic() + 0.1
        while (left := deadline - time.monotonic()) > 0:
            message = master_end.recv(left)
            if message is None:
                break
            if message.arbitration_id == answer_id:
                return bytes(message.data)
    return None


def test_a_master_written_from_the_manual_reads_a_still_imu(tmp_path, master_bus):
    sim_end, master_end = master_bus
    sim, runner = _running(_config(tmp_path), sim_end)
    imu: dict = {}
    try:
        for register in (1, 2, 3, 4):
            answer = _answers(master_end, manual_request(0x01, register), 0x11)
            assert answer is not None, f"no answer to register {register}"
            manual_update(imu, answer)
        # another IMU's request (CANID 2) on the shared 0x6FF: not this one's to answer
        assert _answers(master_end, manual_request(0x02, 1), 0x11, tries=10) is None
    finally:
        sim.stop()
        runner.join(5)
        sim.close()
    # a still base: +g up. One sample of the BMI088's noise at 1 kHz: σ 0.05 m/s², 7.7e-3 rad/s
    assert imu["accel"] == pytest.approx([0, 0, 9.81], abs=0.25)
    assert imu["gyro"] == pytest.approx([0, 0, 0], abs=0.04)
    assert [imu["pitch"], imu["roll"]] == pytest.approx([0, 0], abs=0.01)
    assert imu["q"] == pytest.approx([1, 0, 0, 0], abs=3e-4)


@pytest.mark.parametrize("firmware, request_frame", [
    (1023, can.Message(arbitration_id=0x05, is_extended_id=False, data=[5, 0, 2, 0xCC])),
    (1024, can.Message(arbitration_id=0x05, is_extended_id=False,
                       data=[0xCC, 2, 0, 0xDD, 0, 0, 0, 0])),
])
def test_later_firmware_takes_requests_at_the_imus_own_id(tmp_path, master_bus, firmware,
                                                          request_frame):
    sim_end, master_end = master_bus
    sim, runner = _running(_config(tmp_path, node_id=5, master_id=0x15, firmware=firmware),
                           sim_end)
    try:
        answer = _answers(master_end, request_frame, 0x15)
        # the manual's 0x6FF request is not this firmware's
        legacy = _answers(master_end, manual_request(5, 2), 0x15, tries=10)
    finally:
        sim.stop()
        runner.join(5)
        sim.close()
    assert answer is not None and answer[0] == 2 and legacy is None


def test_a_write_or_a_malformed_request_moves_nothing_and_a_silent_imu_answers_nothing(
        tmp_path):
    config = load_bus_config(_config(tmp_path, node_id=1, firmware=1024)).imus[0]
    port, router = PolledImuPort(config), RecordingRouter()
    port.attach(router)
    request = router.handlers[0x01]
    port.write(ImuSample(np.zeros(3), np.zeros(3), np.array([1.0, 0, 0, 0])))
    request(Frame(0x01, bytes([0xCC, 13, 1, 0xDD, 9, 0, 0, 0])))     # SET_CAN_ID 9: a write
    request(Frame(0x01, bytes([0xCC, 1, 0, 0xDD])))                    # too short
    request(Frame(0x01, bytes([0xCC, 0xFE, 0, 0xDD, 0, 0, 0, 0])))     # SAVE_PARAM, as a read
    assert router.sent == [] and port.refused == 3
    request(Frame(0x01, bytes([0xCC, 1, 0, 0xDD, 0, 0, 0, 0])))
    assert [f.identifier for f in router.sent] == [0x11]
    port.fall_silent()
    request(Frame(0x01, bytes([0xCC, 1, 0, 0xDD, 0, 0, 0, 0])))
    assert len(router.sent) == 1


def test_a_silence_fault_stops_the_answers(tmp_path, master_bus):
    sim_end, master_end = master_bus
    sim, runner = _running(_config(tmp_path), sim_end)
    try:
        before = _answers(master_end, manual_request(0x01, 1), 0x11)
        silent_at = sim.now() + 0.2
        with sim.lock:
            sim.sensor("imu").inject(SensorFaultKind.SILENCE, silent_at)
        wait_until(lambda: sim.now() > silent_at + 0.05)
        after = _answers(master_end, manual_request(0x01, 1), 0x11, tries=10)
    finally:
        sim.stop()
        runner.join(5)
        sim.close()
    assert before is not None and after is None


def test_its_requests_and_answers_count_in_the_bus_load_and_ids(tmp_path):
    # three registers polled at 100 Hz: a request and an answer each
    assert sensor_frames_a_second(_config(tmp_path, poll_hz=100)) == pytest.approx(600)
    # 0x83: node 3's EMCY (CiA 301)
    with pytest.raises(ConfigError, match=r"CAN id 0x083 is used by sensor 'imu' answer and "
                                          r"by node 3"):
        load_bus_config(_config(tmp_path, master_id=0x83))


@pytest.mark.parametrize("sensor, message", [
    ({"node_id": 0}, "'node_id' is 1 to 255"),
    ({"master_id": 300}, "'master_id' is 0 to 255"),
    ({"master_id": 1}, "'master_id' is its 'node_id' (1)"),
    ({"firmware": 1030}, "'firmware' 1030 is none hil knows"),
    ({"rate_hz": 300}, "'rate_hz' 300 is none the product offers"),
    ({"poll_hz": 500}, "'poll_hz' 500 is over its bus' cycle rate"),
    ({"port": "/tmp/x"}, "'port' is not for a dm_imu sensor"),
])
def test_a_bad_dm_imu_entry_is_refused_naming_the_sensor_and_its_line(tmp_path, sensor,
                                                                      message):
    with pytest.raises(ConfigError) as refused:
        load_bus_config(_config(tmp_path, **sensor))
    assert message in str(refused.value) and "ur3_dm_imu.yaml:" in str(refused.value)


def test_a_dm_imu_on_a_bus_of_another_bit_rate_is_refused(tmp_path):
    path = _config(tmp_path)
    config = yaml.safe_load(path.read_text())
    config["buses"][0]["bitrate"] = 500_000
    path.write_text(yaml.safe_dump(config))
    with pytest.raises(ConfigError, match="a DM-IMU-L1 speaks 1,000,000 only"):
        load_bus_config(path)


def test_the_controller_polls_the_imu_and_publishes_what_it_reads(tmp_path):
    config = load_bus_config(_config(tmp_path, link="link6", poll_hz=50,
                                     outputs=["acceleration", "angle"]))
    last = imu_messages(config, 10)[-1]
    assert last.header.frame_id == "link6"
    acceleration = np.array([last.linear_acceleration.x, last.linear_acceleration.y,
                             last.linear_acceleration.z])
    assert np.linalg.norm(acceleration) == pytest.approx(9.81, abs=0.15)
    q = last.orientation                         # from the Euler angles: a unit quaternion
    assert math.isclose(q.w ** 2 + q.x ** 2 + q.y ** 2 + q.z ** 2, 1.0, abs_tol=1e-6)
    # its variance: the yaw and roll fields' step, 360° over 65,535 counts
    assert last.orientation_covariance[0] == pytest.approx(math.radians(360 / 65535) ** 2 / 12)


def test_two_dm_imus_on_a_bus_need_their_own_ids(tmp_path):
    path = _config(tmp_path)
    config = yaml.safe_load(path.read_text())
    config["sensors"].append({"name": "imu2", "product": "dm_imu", "link": "link6",
                              "bus": "arm", "node_id": 1, "master_id": 0x12})
    config["sensors"].append({"name": "imu3", "product": "dm_imu", "link": "link6",
                              "bus": "arm", "node_id": 3, "master_id": 0x11})
    path.write_text(yaml.safe_dump(config))
    with pytest.raises(ConfigError) as refused:
        load_bus_config(path)
    assert "another DM-IMU on bus 'arm' has its node_id 1" in str(refused.value)
    assert ("CAN id 0x011 is used by sensor 'imu' answer and by sensor 'imu3' answer"
            in str(refused.value))
    # two IMUs of their own ids share the manual's 0x6FF for their requests
    config["sensors"] = config["sensors"][:1] + [{**config["sensors"][1], "node_id": 2}]
    path.write_text(yaml.safe_dump(config))
    assert len(load_bus_config(path).imus) == 2


def test_a_sensor_on_the_id_of_the_masters_sync_is_refused(tmp_path):
    with pytest.raises(ConfigError, match=r"CAN id 0x080 is used by the master's SYNC"):
        load_bus_config(_config(tmp_path, master_id=0x80))
