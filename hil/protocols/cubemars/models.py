"""CubeMars AK actuators as their maker and their users' published libraries describe them:
each model's MIT mapping ranges and the figures a bus config sizes a drive with.

Sources (each figure from one of them):

* MIT ranges (P, V, T), gear ratio, torque constant: ``MIT_Params`` of TMotorCANControl
  1.2.6 ("thresholds are in the datasheet for the motor on cubemars.com"; ``Kt_TMotor``,
  the motor side's N·m/A "from the TMotor website"); the AK60-6 V1.1 and V3.0 and the
  AK80-6 ranges from motor-python 0.0.11's ``MITModeLimits`` (bench-validated there).
* Rated and peak torque and current, pole pairs, top output speed: motor-python 0.0.11's
  ``MotorSpec`` ("from CubeMars site specifications") for the AK60-6 V1.1/V3.0 and
  AK80-6; for the others the sources at hand give none, and those models map commands
  (``model: AK80-9``) but are not offered to ``hil init --motor`` (no figures to size with).

Every figure is the output shaft's (after the built-in gear), as the MIT frames carry
them; a servo-mode frame's electrical speed is the rotor's: output rpm x gear x pole pairs.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from hil.protocols.base import PublishedFigures


@dataclass(frozen=True)
class CubeMarsModel(PublishedFigures):
    """One AK model: the MIT mapping and output-shaft figures."""

    name: str
    p_max: float                 # rad: MIT positions map onto [-p_max, p_max]
    v_max: float                 # rad/s
    t_max: float                 # N·m
    gear_ratio: float
    #: N·m per ampere of q-axis current at the output (what servo-mode currents mean)
    torque_constant: float
    pole_pairs: int = 21
    rated_torque: float | None = None     # N·m
    peak_torque: float | None = None      # N·m
    top_rpm: float | None = None          # output shaft

    def erpm(self, output_speed: float) -> float:
        """Electrical rpm of the rotor at ``output_speed`` rad/s."""
        return output_speed * 60 / (2 * math.pi) * self.gear_ratio * self.pole_pairs

    def output_speed(self, erpm: float) -> float:
        """rad/s at the output for an electrical rpm."""
        return erpm / (self.gear_ratio * self.pole_pairs) * 2 * math.pi / 60


def _tmotor(name, ranges, gear, kt_motor, pole_pairs=21) -> CubeMarsModel:
    """A model of TMotorCANControl's table: its torque constant is the motor side's."""
    return CubeMarsModel(name, *ranges, gear, kt_motor * gear, pole_pairs)


def _spec(name, ranges, gear, pole_pairs, rated, peak, peak_current, rpm) -> CubeMarsModel:
    """A model of motor-python's table: the torque constant is its peak torque over its
    peak current."""
    return CubeMarsModel(name, *ranges, gear, peak / peak_current, pole_pairs, rated, peak,
                         rpm)


#: every model by the name a bus config gives (``model: AK80-9``)
MODELS = {model.name: model for model in (
    _tmotor("AK10-9", (12.5, 50.0, 65.0), 9, 0.16),
    _tmotor("AK70-10", (12.5, 50.0, 25.0), 10, 0.095),
    _tmotor("AK80-9", (12.5, 50.0, 18.0), 9, 0.091),
    _spec("AK60-6_V1.1", (12.5, 45.0, 15.0), 6, 14, 3.0, 9.0, 22.7, 560),
    _spec("AK60-6_V3.0", (12.56, 60.0, 12.0), 6, 14, 3.0, 9.0, 11.2, 640),
    _spec("AK80-6", (12.56, 76.0, 12.0), 6, 21, 6.0, 12.0, 20.0, 800),
)}
#: the models ``hil init --motor`` can size with
SIZED = {name: found for name, found in MODELS.items() if found.sizes}


def model(name: str) -> CubeMarsModel:
    """The model of that name (``AK80-9``; ``ak80_9`` and ``AK60-6 V3`` too); KeyError naming
    the known ones otherwise."""
    found = next((m for n, m in MODELS.items() if _plain(n) == _plain(name)), None)
    if found is None:
        raise KeyError(f"no CubeMars model '{name}' (known: {', '.join(MODELS)})")
    return found


def _plain(name: str) -> str:
    """Letters, digits and a version's dot; a version's ".0" dropped (V3.0 is V3)."""
    plain = re.sub(r"[^A-Z0-9.]", "", name.upper())
    return plain[:-2] if plain.endswith(".0") else plain
