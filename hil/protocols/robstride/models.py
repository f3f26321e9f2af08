"""Robstride RS00-RS06 and Xiaomi CyberGear actuators: each model's mapping ranges (what the
uint fields of its frames span) and the figures a bus config sizes a drive with.

Sources, each figure from one of them:

* The ranges P, V, T, Kp, Kd: the maker's own Python package ``robstride-dynamics`` 0.0.1
  (RobStride Dynamics, ``table.py``: ``MODEL_MIT_*_TABLE``) for RS01-RS04; the RS00 manual
  (*RS00使用说明书* 260112, MIT protocol §7.1 and the private protocol's type 2: ±12.57 rad,
  ±33 rad/s, ±14 N·m, firmware 0.0.2.6 and later); RobStride/SampleProgram ``RS01``
  (``Robstride01.cpp``: ±12.5, ±44, ±17) agrees with RS01's. RS05 and RS06: LeRobot 0.4.4's
  ``MOTOR_LIMIT_PARAMS`` (O5 ±50 rad/s ±5.5 N·m, O6 ±50 rad/s ±36 N·m), which agree with the
  models' peak torques where ``robstride-dynamics`` gives RS01's figures for them. A firmware
  that maps otherwise is met with ``p_max``/``v_max``/``t_max`` in the drive's options.
* CyberGear: its instruction manual (belovictor/cybergear-docs, §4.1.2: ±4π, ±30 rad/s,
  ±12 N·m, Kp 0-500, Kd 0-5; §1.3-1.4: 4 N·m rated, 12 peak, 296 rpm no-load, 7.75:1, 0.87
  N·m/A; §4.1.12: iq ±23 A).
* Rated and peak torque, no-load speed, gear: RS00 manual §1 (5 / 14 N·m, 315 rpm, 10:1,
  1.48 N·m/A); the RS02, RS03 and RS04 manuals' specification tables (RS02: 6 N·m rated,
  410 rpm, 7.75:1, its peak taken as its T range, 17 N·m, hil's reading; RS03: 20 / 60 N·m,
  200 rpm, 9:1; RS04: 40 / 120 N·m, 200 rpm, 9:1). For RS01, RS05 and RS06 the
  sources at hand give no such table: those models map frames but are not offered to ``hil
  init --motor``.

Every figure is the output shaft's (after the built-in gear), as the frames carry them.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

from hil.protocols.base import PublishedFigures

#: 4π: the position range of every model (the manuals' "-4π ~ 4π"; 12.57 rad)
FOUR_PI = 4 * math.pi


@dataclass(frozen=True)
class RobstrideModel(PublishedFigures):
    """One model: the ranges its frames map onto and its output-shaft figures."""

    name: str
    v_max: float                  # rad/s: velocities map onto [-v_max, v_max]
    t_max: float                  # N·m
    kp_max: float = 500.0         # N·m/rad: kp maps onto [0, kp_max]
    kd_max: float = 5.0           # N·m·s/rad
    p_max: float = FOUR_PI        # rad
    rated_torque: float | None = None
    peak_torque: float | None = None
    top_rpm: float | None = None  # no-load speed at the output
    gear_ratio: float | None = None
    #: N·m at the output per ampere of iq (current mode's iq_ref, limit_cur); where the
    #: sources give none, the peak torque over the current range (hil's choice)
    torque_constant: float | None = None
    #: the iq range of current mode (A; CyberGear §4.1.12: -23..23)
    current_max: float = 23.0
    #: a Xiaomi CyberGear: its manual's private protocol, without the later types (the module
    #: doc of hil.protocols.robstride)
    cybergear: bool = False

    @property
    def newton_metres_per_ampere(self) -> float:
        return self.torque_constant or (self.peak_torque or self.t_max) / self.current_max


#: every model by the name a bus config gives (``model: RS03``)
MODELS = {model.name: model for model in (
    RobstrideModel("RS00", 33.0, 14.0, p_max=12.57, rated_torque=5.0, peak_torque=14.0,
                   top_rpm=315.0, gear_ratio=10.0, torque_constant=1.48, current_max=16.0),
    RobstrideModel("RS01", 44.0, 17.0),
    RobstrideModel("RS02", 44.0, 17.0, rated_torque=6.0, peak_torque=17.0, top_rpm=410.0,
                   gear_ratio=7.75),
    RobstrideModel("RS03", 50.0, 60.0, 5000.0, 100.0, rated_torque=20.0, peak_torque=60.0,
                   top_rpm=200.0, gear_ratio=9.0, current_max=43.0),
    RobstrideModel("RS04", 15.0, 120.0, 5000.0, 100.0, rated_torque=40.0, peak_torque=120.0,
                   top_rpm=200.0, gear_ratio=9.0, current_max=90.0),
    RobstrideModel("RS05", 50.0, 5.5),
    RobstrideModel("RS06", 50.0, 36.0, 5000.0, 100.0),
    RobstrideModel("CyberGear", 30.0, 12.0, rated_torque=4.0, peak_torque=12.0, top_rpm=296.0,
                   gear_ratio=7.75, torque_constant=0.87, cybergear=True),
)}
#: the models ``hil init --motor`` can size with
SIZED = {name: found for name, found in MODELS.items() if found.sizes}


def model(name: str) -> RobstrideModel:
    """The model of that name (``RS03``; ``rs-03``, ``cybergear`` too); KeyError naming the
    known ones otherwise."""
    found = next((m for n, m in MODELS.items() if _plain(n) == _plain(name)), None)
    if found is None:
        raise KeyError(f"no Robstride model '{name}' (known: {', '.join(MODELS)})")
    return found


def _plain(name: str) -> str:
    return re.sub(r"[^A-Z0-9]", "", name.upper())
