"""Gains for the drives whose own loops, tuned as ``hil sim`` tunes them, are unstable
together: what ``hil init`` writes as their ``gains:``.

A drive without ``gains:`` whose protocol runs its own cascade (CiA 402, ODrive: not the
MIT family, which runs the master's PD) is tuned by ``hil sim`` on the least inertia its
motor sees, every other joint free (:meth:`hil.plant.Plant.motor_inertias`,
:func:`hil.drives.tuning.tuned_gains`: velocity PI Kv = J0 w, Ki = Kv w / 4, position P
w / 4). On one axis that cascade moving an inertia J has the characteristic polynomial
J s^3 + Kv s^2 + (Kv Kp + Ki) s + Ki Kp, stable by Routh's criterion while
Kv (Kv Kp + Ki) > J Ki Kp: J < ROUTH_RATIO J0. The loops act together, though: along a mode
of the robot's inertia (motor side, M v = lambda D v, D the least inertias) they move
lambda times the inertia each was tuned on. Short prismatic stages in series on one axis
(a telescoping arm over its lift) make such a mode, lambda 12.4: the loops oscillated at
8 Hz before any goal, and the demo's first segment, starting from that motion, ran a stage
past its end (EMCY 0x8612). The drives of a mode past ROUTH_RATIO are tuned on
lambda / TARGET_RATIO times their least inertia instead (still tuned_gains), which keeps
that mode within half of the bound.

Fixed bases only: a standing robot's legs see the ground's constraint, which the plant
folds into its least inertias and this module does not (its drives' own bandwidth:
:mod:`hil.commissioning.drive_options`).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from hil.bus_config import SystemConfig
from hil.bus_config.types import Gains
from hil.drives.tuning import tuned_gains
from hil.simulator import bench_plant
from hil.transmissions import SimpleTransmission

#: Routh's bound on the inertia hil's cascade moves, in units of what it was tuned on
ROUTH_RATIO = 8.0
#: where the drives of a mode past the bound are tuned: half of it (hil's choice)
TARGET_RATIO = ROUTH_RATIO / 2
#: a drive takes part in a mode where it moves at least this share of the mode's largest
#: motion (in units of its own least inertia's square root; hil's choice)
PARTICIPATION = 0.1


@dataclass(frozen=True)
class CoupledGains:
    """The gains to write, by actuator, and the largest ratio found (1: none past bound)."""

    gains: dict[str, Gains]
    ratio: float


def coupled_gains(config: SystemConfig) -> CoupledGains:
    """Gains for the drives of ``config`` that take part in a mode of its robot's inertia
    past ROUTH_RATIO (the module's doc): none on a floating base, none for a drive with
    ``gains:`` of its own, the master's PD (``kp`` in its options) or a coupled
    transmission."""
    if config.floating_base:
        return CoupledGains({}, 1.0)
    plant = bench_plant(config)                    # as hil sim builds and tunes it
    least = plant.motor_inertias()
    reductions = {t.actuators[0]: t for t in plant.transmissions
                  if isinstance(t, SimpleTransmission)}
    drives = [d for d in config.drives if d.gains is None and d.actuator in reductions
              and getattr(d.options, "kp", None) is None]
    if not drives:
        return CoupledGains({}, 1.0)
    model = plant.model
    mass = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, plant.data, mass)
    dofs = [model.joint(reductions[d.actuator].joints[0]).dofadr[0] for d in drives]
    ratio = np.array([reductions[d.actuator].reduction for d in drives])
    motor_mass = mass[np.ix_(dofs, dofs)] / np.outer(ratio, ratio)   # q = a / N
    scale = 1.0 / np.sqrt([least[d.actuator] for d in drives])
    ratios, modes = np.linalg.eigh(motor_mass * np.outer(scale, scale))
    factor = np.ones(len(drives))
    for value, mode in zip(ratios, modes.T):
        if value > ROUTH_RATIO:
            motion = np.abs(mode * scale)
            taking_part = motion >= PARTICIPATION * motion.max()
            factor[taking_part] = np.maximum(factor[taking_part], value / TARGET_RATIO)
    gains = {d.actuator: Gains(*tuned_gains(least[d.actuator] * f, d.velocity_bandwidth_hz))
             for d, f in zip(drives, factor) if f > 1.0}
    return CoupledGains(gains, float(max(1.0, ratios.max())))
