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
