"""MyActuator RMD-X actuators, each model's figures at the output shaft.

Source: ``actuator_constants.hpp`` of 2b-t/myactuator_rmd (the C++ driver SDK with Python
bindings, "in accordance with the manufacturer's data sheets"): reduction ratio, rated
speed (rpm), rated current (A), rated torque (N·m), torque constant (rated torque over rated
current, N·m/A at the output). The peak torque is the number in the model's name (MyActuator
names its "-NN" series by it: RMD-X8-20 peaks at 20 N·m; hil's reading of the name, as the
SDK gives no peak). The SDK gives these models no no-load speed: hil takes the rated speed
as the top speed (a conservative choice). The SDK's "rotor inertia" is not said to be on
either side of the gear, so none is added to the joint.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass


@dataclass(frozen=True)
class RmdModel:
    """One RMD-X model."""

    name: str
    gear_ratio: float
    rated_rpm: float             # output shaft
    rated_current: float         # A
    rated_torque: float          # N·m
    peak_torque: float           # N·m
    pole_pairs: int = 14

    @property
    def torque_constant(self) -> float:
        """N·m per ampere of torque current at the output (the SDK's rated torque over
        rated current)."""
        return self.rated_torque / self.rated_current

    @property
    def no_load_speed(self) -> float:
        """rad/s at the output (the rated speed: the module doc)."""
        return self.rated_rpm * 2 * math.pi / 60

    @property
    def reflected_inertia(self) -> float:
        """0: the sources give no rotor inertia (``hil init`` estimates one:
        ``hil.commissioning.sizing.estimated_reflected_inertia``)."""
        return 0.0


#: every model by the name a bus config gives (``model: X8-20``), from the SDK's classes
#: X4_3, X4_24, X6_7, X6_8, X6_40, X8_20, X8_25, X8_60, X8_90, X10_40, X10_100, X12_150,
#: X15_400 (ratio, rated rpm, rated A, rated N·m, pole pairs)
MODELS = {model.name: model for model in (
    RmdModel("X4-3", 6, 200, 2.0, 1.5, 3, 14),
    RmdModel("X4-24", 36, 100, 3.5, 9, 24, 14),
    RmdModel("X6-7", 6, 400, 4.0, 3.5, 7, 14),
    RmdModel("X6-8", 8, 310, 3.6, 4.5, 8, 14),
    RmdModel("X6-40", 36, 90, 5.2, 18, 40, 14),
    RmdModel("X8-20", 6, 190, 5.2, 10, 20, 20),
    RmdModel("X8-25", 9, 110, 3.2, 10, 25, 21),
    RmdModel("X8-60", 36, 40, 4.0, 30, 60, 20),
    RmdModel("X8-90", 18, 130, 10, 25, 90, 21),
    RmdModel("X10-40", 7, 165, 6.5, 15, 40, 21),
    RmdModel("X10-100", 35, 50, 6.7, 50, 100, 21),
    RmdModel("X12-150", 12, 100, 15, 50, 150, 21),
    RmdModel("X15-400", 11.4, 80, 23, 130, 400, 21),
)}


def model(name: str) -> RmdModel:
    """The model of that name (``X8-20``; ``RMD-X8-20`` and ``x8_20`` too); KeyError naming
    the known ones otherwise."""
    plain = re.sub(r"[^A-Z0-9]", "", name.upper()).removeprefix("RMD")
    found = next((m for n, m in MODELS.items() if re.sub(r"[^A-Z0-9]", "", n) == plain), None)
    if found is None:
        raise KeyError(f"no MyActuator model '{name}' (known: {', '.join(MODELS)})")
    return found
