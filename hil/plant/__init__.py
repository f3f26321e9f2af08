"""The MuJoCo plant: physics of the robot behind the virtual drives."""

from hil.plant.builder import DEFAULT_TIMESTEP, ActuatorBinding, build_spec
from hil.plant.shapes import rpy_to_quat
from hil.plant.plant import INITIAL_MARGIN, Plant

__all__ = ["ActuatorBinding", "DEFAULT_TIMESTEP", "INITIAL_MARGIN", "Plant", "build_spec",
           "rpy_to_quat"]
