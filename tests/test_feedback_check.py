"""The plausibility check of joint feedback, and where the plant starts a robot."""

from __future__ import annotations

import numpy as np

from conftest import CORPUS
from hil.description import PackagePath, load_description
from hil.hardware.feedback import JointFeedback, PlausibilityCheck
from hil.plant import Plant
from hil.plant.plant import INITIAL_MARGIN

ARM = CORPUS / "real_world" / "arm_folder" / "urdf" / "arm.urdf.xacro"     # elbow 0.2..2.5


def _robot():
    return load_description(ARM, PackagePath((CORPUS / "real_world",)))


def _feedback(positions) -> JointFeedback:
    positions = np.array(positions, dtype=float)
    return JointFeedback(positions, np.zeros_like(positions), np.zeros_like(positions),
                         np.zeros_like(positions), ("", ""))


def test_a_drive_not_heard_yet_is_not_judged_by_its_default_values():
    check = PlausibilityCheck(_robot(), ("shoulder", "elbow"))
    used, implausible = check.check(_feedback([0.0, 0.0]), np.array([True, False]))
    assert implausible == [] and used.positions[1] == 0.0


def test_feedback_beyond_a_joints_reach_is_named_and_not_used():
    check = PlausibilityCheck(_robot(), ("shoulder", "elbow"))
    check.check(_feedback([0.1, 1.0]), np.array([True, True]))
    used, implausible = check.check(_feedback([0.1, -5.0]), np.array([True, True]))
    (k, why), = implausible
    assert k == 1 and "joint 'elbow' measured at -5" in why
    assert used.positions[1] == 1.0                     # its last plausible value


def test_with_every_drive_heard_every_joint_is_judged():
    check = PlausibilityCheck(_robot(), ("shoulder", "elbow"))
    used, implausible = check.check(_feedback([0.0, -5.0]))            # heard: None, all
    assert [k for k, _ in implausible] == [1]


def test_a_nan_or_infinite_measurement_is_implausible_and_never_used():
    check = PlausibilityCheck(_robot(), ("shoulder", "elbow"))
    (_, low), (_, high) = check.reach                   # the elbow's reach
    for bad in (np.nan, np.inf, -np.inf):               # no plausible feedback before them
        used, implausible = check.check(_feedback([0.1, bad]))
        assert [k for k, _ in implausible] == [1] and low <= used.positions[1] <= high
    check.check(_feedback([0.1, 1.0]))
    for bad in (np.nan, np.inf, -np.inf):
        used, implausible = check.check(_feedback([0.1, bad]))
        assert [k for k, _ in implausible] == [1] and used.positions[1] == 1.0


def test_the_plant_starts_a_joint_whose_range_excludes_zero_inside_its_range():
    plant = Plant(_robot())
    shoulder, elbow = plant.joint_positions()
    assert shoulder == 0.0
    assert elbow == np.float64(0.2 + INITIAL_MARGIN * (2.5 - 0.2))
