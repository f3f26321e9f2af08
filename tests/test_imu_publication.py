"""The controller's side of an IMU: read off its serial port as a USB device's is, published
as sensor_msgs/Imu on hil's keys and the ROS face, recorded."""

from __future__ import annotations

import math
import queue
import time

import numpy as np
import pytest
import serial
from conftest import imu_messages
from ros_spec_client import SpecClient
from test_wit_imu import _config

from hil.bus_config import load_bus_config
from hil.hardware.sensor_states import ImuDescription
from hil.hardware.serial_imu import SerialImu
from hil.messaging import cdr
from hil.messaging.sensors import ImuMessage
from hil.messaging.ros.face import RosControlFace, RosSettings
from hil.messaging.ros.router import open_router
from hil.protocols import wit
from hil.protocols.imu import ImuSample
from hil.realtime import LOCK_STEP
from hil.sensors.serial_port import PseudoTerminal
from hil.stack import running_stack
from hil.zenoh_session import free_loopback_port


@pytest.fixture
def imu_config(tmp_path):
    """The ur3 (in-process buses) with a WIT IMU on its last link at 200 Hz, its port in the
    test's folder."""
    return load_bus_config(_config(tmp_path, link="link6", rate_hz=200))


def test_the_controller_publishes_the_imu_it_reads_as_sensor_msgs_imu(imu_config):
    # 0.5 s of samples: the first 15 or so (75 ms) see the arm come up (up to 10.24 m/s²)
    messages = imu_messages(imu_config, 100)
    last = messages[-1]
    assert last.header.frame_id == "link6"
    # the last 20 (the noise's 0.045 m/s² a sample averaged): the arm still, gravity alone
    # (CI, 2026-12-07: the 20th sample read 9.96 on a loaded host, inside the bring-up)
    accelerations = np.array([[m.linear_acceleration.x, m.linear_acceleration.y,
                               m.linear_acceleration.z] for m in messages[-20:]])
    assert np.linalg.norm(accelerations, axis=1).mean() == pytest.approx(9.81, abs=0.15)
    q = last.orientation
    assert math.isclose(q.w ** 2 + q.x ** 2 + q.y ** 2 + q.z ** 2, 1.0, abs_tol=1e-3)
    # the covariances say what hil models: the gyroscope's white noise at 200 Hz
    expected = ImuDescription.of(imu_config.sensors[0]).variances
    assert last.angular_velocity_covariance[0] == pytest.approx(expected[1])
    stamps = [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in messages]
    assert stamps == sorted(stamps) and abs(stamps[-1] - time.time()) < 30


def test_a_port_another_program_holds_is_left_to_it_and_said_so(tmp_path):
    config = load_bus_config(_config(tmp_path)).sensors[0]
    port = PseudoTerminal(config.port)
    reader = SerialImu(config)
    try:
        with serial.Serial(str(config.port), 460800, exclusive=True):
            assert reader.poll() == []
            assert reader.problem == f"{config.port} is held by another program"
    finally:
        reader.close()
        port.close()


def test_the_reader_opens_a_port_that_appears_later_and_reads_its_samples(tmp_path,
                                                                         monkeypatch):
    config = load_bus_config(_config(tmp_path)).sensors[0]
    monkeypatch.setattr("hil.hardware.serial_imu.RETRY", 0.0)
    reader = SerialImu(config, clock=lambda: 42.0)
    assert reader.poll() == [] and "No such file" in reader.problem
    port = PseudoTerminal(config.port)
    try:
        assert reader.poll() == [] and reader.problem is None       # opened, nothing yet
        sample = ImuSample(np.array([0.0, 0.0, 9.81]), np.zeros(3),
                               np.array([1.0, 0.0, 0.0, 0.0]))
        port.write(wit.encode(sample, config.outputs) * 2)
        states = reader.poll()
        assert [s.received for s in states] == [42.0, 42.0] and states[0].frame == "base_link"
        assert states[0].reading.acceleration == pytest.approx([0, 0, 9.81], abs=0.005)
    finally:
        reader.close()
        port.close()


#: sensor_msgs/msg/Imu's RIHS01 hash (Jazzy to Lyrical: tests/test_ros_type_hashes.py holds
#: hil's against ROS's own computation of it)
IMU_HASH = "RIHS01_7d9a00ff131080897a5ec7e26e315954b8eae3353c3f995c55faf71574000b5b"


def test_the_ros_face_publishes_each_imu_as_imu_sensor_broadcaster_does(imu_config):
    endpoint = f"tcp/127.0.0.1:{free_loopback_port()}"
    router = open_router((endpoint,))
    settings = RosSettings(router=endpoint)
    face = [lambda node: RosControlFace(settings, node.controller, node.clock,
                                        "<robot name='ur3'/>", node.reset_faults)]
    client = None
    try:
        with running_stack(imu_config, LOCK_STEP, faces=face):
            client = SpecClient(endpoint)
            token = client.find("MP", "/imu_sensor_broadcaster/imu")
            assert (token.type_name, token.type_hash) == ("sensor_msgs::msg::dds_::Imu_",
                                                          IMU_HASH)
            arrived: queue.SimpleQueue = queue.SimpleQueue()
            subscriber = client.session.declare_subscriber(
                token.key(0), lambda sample: arrived.put(sample.payload.to_bytes()))
            try:
                message = cdr.decode(arrived.get(timeout=30), cdr.IMU)
            finally:
                subscriber.undeclare()
    finally:
        if client is not None:
            client.close()
        router.close()
    assert message.header.frame_id == "link6" and message.linear_acceleration_covariance[0] > 0


@pytest.mark.parametrize("key_expr, payload, said", [
    ("hil/ur3/sensors/imu/imu", b"\x00\x01\x00\x00garbage", "malformed sensor_msgs/msg/Imu"),
    ("hil/ur3/sensors/imu/imu", b"", "malformed sensor_msgs/msg/Imu"),
    ("hil/ur3/joint_states", cdr.ImuCdr("l", (0, 0, 0)).encode(0, None, None, None),
     "is no IMU's key"),
])
def test_a_malformed_imu_sample_is_refused_naming_what(key_expr, payload, said):
    with pytest.raises(ValueError, match=said):
        ImuMessage.decode(key_expr, payload)


def test_a_sample_decodes_to_what_was_sent_and_a_missing_field_to_nan():
    payload = cdr.ImuCdr("pelvis", (0, 1e-4, 1e-3)).encode(
        3.25, None, (0.1, -0.2, 0.3), (0.0, 0.0, 9.81))
    message = ImuMessage.decode("hil/g1/sensors/imu/imu", payload)
    assert (message.sensor, message.stamp) == ("imu", 3.25)
    assert np.isnan(message.orientation).all()
    assert message.angular_velocity.tolist() == [0.1, -0.2, 0.3]
