"""hil's hand-packed CDR against rosbags' serialiser: the same bytes."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from hil.messaging import cdr

NAMES = st.lists(st.text(max_size=9), max_size=8)
STAMPS = st.floats(min_value=0, max_value=2**31 - 1, allow_nan=False)


@given(names=NAMES, stamp=STAMPS, data=st.data())
def test_joint_states_pack_as_rosbags_serialises_them(names, stamp, data):
    values = st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=len(names),
                      max_size=len(names))
    positions, velocities, efforts = (np.array(data.draw(values), dtype=np.float64)
                                      for _ in range(3))
    packed = cdr.JointStateCdr(names).encode(stamp, positions, velocities, efforts)
    assert packed == cdr.encode(cdr.joint_state_msg(stamp, names, positions, velocities,
                                                    efforts))
    decoded = cdr.decode(packed, cdr.JOINT_STATE)
    assert list(decoded.name) == names
    assert decoded.position.tobytes() == positions.tobytes()


def test_joint_states_of_the_wrong_size_are_refused():
    with pytest.raises(ValueError, match="2 joints, values for 1, 2, 2"):
        cdr.JointStateCdr(["a", "b"]).encode(0.0, [1.0], [1.0, 2.0], [1.0, 2.0])


def test_a_stamp_ros_cannot_carry_is_refused():
    with pytest.raises(ValueError, match="not a time ROS 2 can carry"):
        cdr.JointStateCdr(["a"]).encode(math.inf, [1.0], [1.0], [1.0])


FINITE = st.floats(allow_nan=False, allow_infinity=False, width=64)
TRIPLES = st.tuples(FINITE, FINITE, FINITE)


def _vector3(values) -> object:
    x, y, z = values
    return cdr.msg("geometry_msgs/msg/Vector3", x=x, y=y, z=z)


@given(frame=st.text(max_size=12), stamp=STAMPS,
       orientation=st.none() | st.tuples(FINITE, FINITE, FINITE, FINITE),
       rate=st.none() | TRIPLES, acceleration=st.none() | TRIPLES,
       variances=st.tuples(FINITE, FINITE, FINITE))
def test_an_imu_sample_packs_as_rosbags_serialises_it(frame, stamp, orientation, rate,
                                                      acceleration, variances):
    packed = cdr.ImuCdr(frame, variances).encode(stamp, orientation, rate, acceleration)

    def covariance(field, variance) -> np.ndarray:
        if field is None:                      # sensor_msgs/Imu: element 0 at -1, unknown
            return np.array([-1.0] + [0.0] * 8)
        return np.diag([variance] * 3).ravel()

    w, x, y, z = orientation if orientation is not None else (0.0, 0.0, 0.0, 0.0)
    message = cdr.msg(cdr.IMU, header=cdr.header(stamp, frame),
                      orientation=cdr.msg("geometry_msgs/msg/Quaternion", x=x, y=y, z=z, w=w),
                      orientation_covariance=covariance(orientation, variances[0]),
                      angular_velocity=_vector3(rate or (0.0, 0.0, 0.0)),
                      angular_velocity_covariance=covariance(rate, variances[1]),
                      linear_acceleration=_vector3(acceleration or (0.0, 0.0, 0.0)),
                      linear_acceleration_covariance=covariance(acceleration, variances[2]))
    assert packed == cdr.encode(message)


@given(frame=st.text(max_size=12), stamp=STAMPS, force=TRIPLES, torque=TRIPLES)
def test_a_wrench_packs_as_rosbags_serialises_it(frame, stamp, force, torque):
    packed = cdr.WrenchCdr(frame).encode(stamp, force, torque)
    message = cdr.msg(cdr.WRENCH_STAMPED, header=cdr.header(stamp, frame),
                      wrench=cdr.msg("geometry_msgs/msg/Wrench", force=_vector3(force),
                                     torque=_vector3(torque)))
    assert packed == cdr.encode(message)
