"""What `hil up` judges of a running robot from what it hears: here, a floating base that
fell (a demo whose joints track with the robot lying on the floor has not succeeded)."""

from __future__ import annotations

import numpy as np

from hil.cli.run_progress import FALLEN_SHARE, Progress
from hil.messaging.scene import SceneState


def _scene(base_height: float | None) -> SceneState:
    base = None if base_height is None else (np.array([0.0, 0.0, base_height]),
                                             np.array([1.0, 0.0, 0.0, 0.0]))
    return SceneState(0.0, 0.0, (), np.zeros((0, 3)), np.zeros((0, 4)), np.zeros((0, 3)),
                      np.zeros((0, 3)), base)


def test_a_floating_base_that_came_down_to_the_floor_is_told_fallen_with_its_heights():
    progress = Progress()
    for height in (0.792, 0.788, 0.49, 0.076, 0.12):      # the G1 toppling over, then lying
        progress.on_scene(SceneState.decode(_scene(height).encode()))
    assert progress.fallen() == ("the robot fell: its base came down from 0.792 m to "
                                 "0.076 m")


def test_a_base_that_sags_or_rocks_and_a_fixed_base_have_not_fallen():
    standing, fixed = Progress(), Progress()
    for height in (0.792, 0.786, 0.79, 0.792 * FALLEN_SHARE + 1e-6):
        standing.on_scene(_scene(height))
        fixed.on_scene(_scene(None))
    assert standing.fallen() is None
    assert fixed.fallen() is None
