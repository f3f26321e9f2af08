"""How the joints stop after a cancel or an abort (the JTC's set_hold_position, or with
``decelerate_on_cancel`` its decelerate_to_hold_position: ros2_controllers jazzy,
joint_trajectory_controller/doc/decelerate_on_cancel.rst)."""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from hil.controllers.parameters import JtcParameters
from hil.controllers.stop_ramp import StopRamp


def stop_ramp(parameters: JtcParameters, joint_names: Iterable[str], now: float,
              position: np.ndarray, velocity: np.ndarray) -> StopRamp | None:
    """The ramp down to rest from the measured ``position`` and ``velocity`` with
    decelerate_on_cancel where every joint has a deceleration, else None: hold the measured
    position."""
    deceleration = np.array([parameters.constraint(j).max_deceleration_on_cancel
                             for j in joint_names])
    if parameters.decelerate_on_cancel and np.all(deceleration > 0):
        return StopRamp(now, position.copy(), velocity.copy(), deceleration)
    return None
