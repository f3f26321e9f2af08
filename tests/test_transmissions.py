"""Transmission maps: ros2_control's formulas, both directions, all quantities."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, strategies as st

from hil.description import load_description
from hil.transmissions import (
    DifferentialTransmission, FourBarLinkageTransmission, SimpleTransmission, TransmissionStack,
    build_transmissions,
)
from conftest import COUPLED_URDF

finite = st.floats(-1e3, 1e3, allow_nan=False)
ratio = st.one_of(st.floats(0.01, 500), st.floats(-500, -0.01))
pair = st.tuples(finite, finite)
ratios = st.tuples(ratio, ratio)


def test_simple_reduction_100_with_offset_by_hand():
    t = SimpleTransmission("j", "m", reduction=100.0, offset=0.5)
    assert t.joint_to_actuator_position([1.2]) == pytest.approx([70.0])
    assert t.actuator_to_joint_position([70.0]) == pytest.approx([1.2])
    assert t.joint_to_actuator_velocity([0.3]) == pytest.approx([30.0])
    assert t.actuator_to_joint_velocity([30.0]) == pytest.approx([0.3])
    assert t.joint_to_actuator_effort([50.0]) == pytest.approx([0.5])
    assert t.actuator_to_joint_effort([0.2]) == pytest.approx([20.0])
    assert t.actuator_effort_limits([100.0]) == pytest.approx([1.0])


def test_zero_reduction_is_refused():
    with pytest.raises(ValueError):
        SimpleTransmission("j", "m", reduction=0.0)
    with pytest.raises(ValueError):
        DifferentialTransmission(("a", "b"), ("m", "n"), (1.0, 0.0), (1.0, 1.0))


# Reference formulas, written out as in ros2_control's transmission_interface headers.

def differential_reference(ar, jr, off):
    def a2j_pos(a):
        return [(a[0] / ar[0] + a[1] / ar[1]) / (2 * jr[0]) + off[0],
                (a[0] / ar[0] - a[1] / ar[1]) / (2 * jr[1]) + off[1]]

    def j2a_pos(q):
        d = [q[0] - off[0], q[1] - off[1]]
        return [(d[0] * jr[0] + d[1] * jr[1]) * ar[0], (d[0] * jr[0] - d[1] * jr[1]) * ar[1]]

    def a2j_vel(a):
        return [(a[0] / ar[0] + a[1] / ar[1]) / (2 * jr[0]),
                (a[0] / ar[0] - a[1] / ar[1]) / (2 * jr[1])]

    def j2a_vel(v):
        return [(v[0] * jr[0] + v[1] * jr[1]) * ar[0], (v[0] * jr[0] - v[1] * jr[1]) * ar[1]]

    def a2j_eff(t):
        return [jr[0] * (t[0] * ar[0] + t[1] * ar[1]), jr[1] * (t[0] * ar[0] - t[1] * ar[1])]

    def j2a_eff(t):
        return [(t[0] / jr[0] + t[1] / jr[1]) / (2 * ar[0]),
                (t[0] / jr[0] - t[1] / jr[1]) / (2 * ar[1])]
    return a2j_pos, j2a_pos, a2j_vel, j2a_vel, a2j_eff, j2a_eff


def four_bar_reference(ar, jr, off):
    def a2j_pos(a):
        return [a[0] / (jr[0] * ar[0]) + off[0],
                (a[1] / ar[1] - a[0] / (jr[0] * ar[0])) / jr[1] + off[1]]

    def j2a_pos(q):
        d = [q[0] - off[0], q[1] - off[1]]
        return [d[0] * jr[0] * ar[0], (d[0] + d[1] * jr[1]) * ar[1]]

    def a2j_vel(a):
        return [a[0] / (jr[0] * ar[0]), (a[1] / ar[1] - a[0] / (jr[0] * ar[0])) / jr[1]]

    def j2a_vel(v):
        return [v[0] * jr[0] * ar[0], (v[0] + v[1] * jr[1]) * ar[1]]

    def a2j_eff(t):
        return [jr[0] * t[0] * ar[0], jr[1] * (t[1] * ar[1] - jr[0] * t[0] * ar[0])]

    def j2a_eff(t):
        return [t[0] / (ar[0] * jr[0]), (t[0] + t[1] / jr[1]) / ar[1]]
    return a2j_pos, j2a_pos, a2j_vel, j2a_vel, a2j_eff, j2a_eff


def methods(t):
    return (t.actuator_to_joint_position, t.joint_to_actuator_position,
            t.actuator_to_joint_velocity, t.joint_to_actuator_velocity,
            t.actuator_to_joint_effort, t.joint_to_actuator_effort)


@pytest.mark.parametrize("cls, reference", [(DifferentialTransmission, differential_reference),
                                            (FourBarLinkageTransmission, four_bar_reference)],
                         ids=["differential", "four_bar"])
@given(ar=ratios, jr=ratios, off=pair, x=pair)
def test_coupled_maps_match_ros2_control_formulas(cls, reference, ar, jr, off, x):
    t = cls(("j1", "j2"), ("a1", "a2"), ar, jr, off)
    for ours, theirs in zip(methods(t), reference(ar, jr, off)):
        expected = theirs(x)
        assert ours(x) == pytest.approx(expected, rel=1e-9, abs=1e-9 * max(1, *map(abs, expected)))


def round_trips(t, x):
    x = np.asarray(x, dtype=float)
    scale = 1e-9 * max(1.0, float(np.abs(x).max()))
    for to_actuator, to_joint in ((t.joint_to_actuator_position, t.actuator_to_joint_position),
                                  (t.joint_to_actuator_velocity, t.actuator_to_joint_velocity),
                                  (t.joint_to_actuator_effort, t.actuator_to_joint_effort)):
        assert to_joint(to_actuator(x)) == pytest.approx(x, abs=scale * 1e3)
        assert to_actuator(to_joint(x)) == pytest.approx(x, abs=scale * 1e3)


@given(reduction=ratio.filter(lambda r: abs(r) >= 0.1), offset=finite, x=finite)
def test_simple_round_trips_all_quantities(reduction, offset, x):
    round_trips(SimpleTransmission("j", "m", reduction, offset), [x])


@given(ar=ratios, jr=ratios, off=pair, x=pair)
def test_differential_round_trips_all_quantities(ar, jr, off, x):
    round_trips(DifferentialTransmission(("j1", "j2"), ("a1", "a2"), ar, jr, off), x)


@given(ar=ratios, jr=ratios, off=pair, x=pair)
def test_four_bar_round_trips_all_quantities(ar, jr, off, x):
    round_trips(FourBarLinkageTransmission(("j1", "j2"), ("a1", "a2"), ar, jr, off), x)


@given(ar=ratios, jr=ratios, tau=pair)
def test_differential_conserves_power(ar, jr, tau):
    """Its effort map is the inverse transpose of its position map."""
    t = DifferentialTransmission(("j1", "j2"), ("a1", "a2"), ar, jr)
    assert t.actuator_to_joint_effort(tau) == pytest.approx(t.position_matrix.T @ tau,
                                                            rel=1e-9, abs=1e-6)


def test_transmissions_built_from_urdf_use_ros1_and_ros2_reductions(package_path):
    description = load_description(COUPLED_URDF, package_path)
    four_bar, differential = build_transmissions(description)
    assert isinstance(four_bar, FourBarLinkageTransmission)
    assert four_bar.actuator_reductions == (50.0, 40.0)
    assert four_bar.joint_reductions == (2.0, 1.5)
    assert list(four_bar.joint_offsets) == [0.1, 0.0]
    assert isinstance(differential, DifferentialTransmission)
    assert differential.actuators == ("wrist_left_motor", "wrist_right_motor")
    assert differential.joint_reductions == (1.0, -1.0)


@given(ar=ratios, jr=ratios, reduction=ratio, off=pair, x=st.tuples(finite, finite, finite))
def test_a_stack_in_any_order_maps_like_its_parts(ar, jr, reduction, off, x):
    differential = DifferentialTransmission(("j1", "j2"), ("m1", "m2"), ar, jr, off)
    simple = SimpleTransmission("j3", "m3", reduction, 0.25)
    stack = TransmissionStack((differential, simple), ("j3", "j1", "j2"), ("m2", "m3", "m1"))
    joints = np.array([x[2], x[0], x[1]])                   # j3, j1, j2
    for quantity in ("position", "velocity", "effort"):
        stacked = getattr(stack, f"joint_to_actuator_{quantity}")(joints)
        first = getattr(differential, f"joint_to_actuator_{quantity}")(joints[1:])
        second = getattr(simple, f"joint_to_actuator_{quantity}")(joints[:1])
        assert stacked == pytest.approx([first[1], second[0], first[0]], rel=1e-9, abs=1e-6)
        back = getattr(stack, f"actuator_to_joint_{quantity}")(stacked)
        assert back == pytest.approx(joints, rel=1e-6, abs=1e-6)


def test_a_stack_refuses_a_joint_in_two_transmissions():
    with pytest.raises(ValueError, match="exactly one transmission"):
        TransmissionStack((SimpleTransmission("j", "m1", 2.0), SimpleTransmission("j", "m2", 3.0)),
                          ("j",), ("m1", "m2"))


@given(ar=ratios, jr=ratios, reduction=ratio, off=pair,
       a=st.tuples(*[finite] * 9))
def test_a_cycles_feedback_in_one_product_maps_as_the_three_maps(ar, jr, reduction, off, a):
    """actuator_to_joint_feedback: positions, velocities and efforts one after the other."""
    stack = TransmissionStack((DifferentialTransmission(("j1", "j2"), ("m1", "m2"), ar, jr, off),
                               SimpleTransmission("j3", "m3", reduction, 0.25)),
                              ("j3", "j1", "j2"), ("m2", "m3", "m1"))
    measured = np.array(a)
    expected = np.concatenate([stack.actuator_to_joint_position(measured[:3]),
                               stack.actuator_to_joint_velocity(measured[3:6]),
                               stack.actuator_to_joint_effort(measured[6:])])
    scale = 1e-12 * max(1.0, float(np.abs(expected).max()))
    assert stack.actuator_to_joint_feedback(measured) == pytest.approx(expected, abs=scale)
