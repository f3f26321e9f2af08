"""Damiao DM-J motors as their maker publishes them: each model's mapping ranges and the
figures a bus config sizes a drive with.

Sources (each figure from one of them, none guessed):

* PMAX, VMAX, TMAX: the ``Limit_Param`` table of Damiao's own Python sample code
  (``DM_CAN.py`` of DM_Control_Python: ``[12.5, 30, 10]`` for the 4310, ``[12.5, 8, 28]`` for
  the 4340, ...); the 3507's from the maker's specification table (below).
* Rated and peak torque, gear ratio, no-load speed, rotor inertia, torque constant, pole
  pairs, phase resistance and inductance, flux linkage, the driver's maximum current: the
  specification table of Seeed Studio's "Damiao Series Motors" guide, which reproduces the
  DM-J manuals (DM-J4310-2EC V1.1, DM-J4340-2EC, ...). Torques and speeds are the output
  shaft's, what the motor's CAN frames carry (its ``Gr`` register folds the gear in).

A published client library may carry other ranges (python ``damiao-motor`` 1.0.6 maps the
4340 with VMAX 10, the 48 V variant's): a real motor maps with the ranges in its PMAX/VMAX/
TMAX registers, and so does hil's, read back as any client reads them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class DamiaoModel:
    """One DM-J model: output-shaft figures."""

    name: str
    p_max: float               # rad: positions map onto [-p_max, p_max]
    v_max: float               # rad/s
    t_max: float               # N·m
    gear_ratio: float
    rated_torque: float        # N·m
    peak_torque: float         # N·m
    no_load_rpm: float         # output shaft, at the rated supply
    rotor_inertia: float       # kg·m², the rotor's (before the gear)
    torque_constant: float     # N·m/A at the output
    pole_pairs: int
    phase_resistance: float    # ohm
    phase_inductance: float    # H
    flux_linkage: float        # Wb
    driver_max_current: float  # A
    supply_voltage: float = 24.0

    @property
    def no_load_speed(self) -> float:
        """rad/s at the output shaft."""
        return self.no_load_rpm * 2 * math.pi / 60

    @property
    def reflected_inertia(self) -> float:
        """The rotor's inertia as the output shaft feels it (kg·m²): J·N²."""
        return self.rotor_inertia * self.gear_ratio ** 2


def _model(name, ranges, gear, rated, peak, rpm, inertia, kt, npp, rs, ls_uh, flux, imax,
           volts=24.0) -> DamiaoModel:
    return DamiaoModel(name, *ranges, gear, rated, peak, rpm, inertia, kt, npp, rs,
                       ls_uh * 1e-6, flux, imax, volts)


#: every model by the name a bus config gives (``model: DM4340``)
MODELS = {model.name: model for model in (
    _model("DM3507", (12.566, 50, 5), 7, 0.8, 3, 460, 8.7e-6, 0.5439, 14, 0.8, 235, 0.0037,
           10.261194),
    _model("DM4310", (12.5, 30, 10), 10, 3, 7, 200, 1.8e-5, 0.945, 14, 0.85, 345, 0.0045,
           10.261194),
    _model("DM4310_48V", (12.5, 50, 10), 10, 3, 7, 400, 1.8e-5, 0.945, 14, 0.85, 345, 0.0045,
           10.261194, 48.0),
    _model("DM4340", (12.5, 8, 28), 40, 9, 27, 52.5, 2.0e-5, 4.074, 14, 0.88, 360, 0.00485,
           10.261194),
    _model("DM4340_48V", (12.5, 10, 28), 40, 9, 27, 100, 2.0e-5, 4.074, 14, 0.88, 360,
           0.00485, 10.261194, 48.0),
    _model("DM6006", (12.5, 45, 20), 6, 4, 11, 226, 5.8e-5, 0.7308, 14, 0.435, 270, 0.0058,
           20.52238806),
    _model("DM8006", (12.5, 45, 40), 6, 8, 20, 194.2, 1.15e-4, 1.0206, 21, 0.4, 215, 0.0054,
           41.04477612),
    _model("DM8009", (12.5, 45, 54), 9, 20, 40, 168, 1.95e-4, 1.261575, 21, 0.145, 80, 0.00445,
           41.04477612),
    _model("DM10010L", (12.5, 25, 200), 10, 40, 120, 100, 5.56e-4, 2.00025, 21, 0.11, 85,
           0.00635, 99.7),
    _model("DM10010", (12.5, 20, 200), 10, 40, 150, 75, 5.5e-4, 2.59875, 21, 0.125, 100,
           0.00825, 100.0),
)}


def model(name: str) -> DamiaoModel:
    """The model of that name (``DM4340``; ``4340`` and ``DM-J4340`` too); KeyError naming
    the known ones otherwise."""
    key = name.upper().replace("DM-J", "DM").replace("-", "_")
    key = key if key.startswith("DM") else f"DM{key}"
    if key not in MODELS:
        raise KeyError(f"no Damiao model '{name}' (known: {', '.join(MODELS)})")
    return MODELS[key]
