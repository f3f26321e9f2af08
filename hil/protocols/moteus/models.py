"""The moteus controllers and the motors mjbots characterises for them, with the figures a
bus config sizes a drive with.

Sources (github.com/mjbots/moteus):

* controllers: docs/reference/hardware.md, "Electrical Limits" (supply range, peak phase
  current) and the controller classes of mjbots' performance analysis tool, docs/mpat.html
  (``MoteusR4``, ``MoteusC1``, ``MoteusN1``, ``MoteusX1``: ``maxCurrent``); the firmware's
  own ``servo.max_current_A`` defaults agree (fw/bldc_servo_structs.h: 100 A r4 and n1,
  20 A c1, 120 A x1);
* motors: the motor classes of docs/mpat.html (``MJ5208``, ``MAD8318``, ``BE8108``; not
  the gimbal-wound ``GBM5208``, whose current its supply limits, not the controller): Kv,
  phase resistance to the virtual centre, poles, rotor inertia, the winding's maximum
  temperature, the thermal resistance with no cooling, and the torque model
  ``getRotorTorque``: ``kt = 8.3 / Kv`` up to ``rotationCurrentCutoff``, then
  ``rotationTorqueScale * log2(1 + (I - cutoff) * rotationCurrentScale)`` more.

What hil derives from them (mpat's own formulas, at mpat's defaults, 24 V and 25 °C ambient):
the peak torque is the motor's torque at the controller's peak current; the rated torque
is the torque at the current whose copper loss (``1.5 I² R``) the uncooled motor sheds at
its maximum temperature (mpat ``getCurrentFromThermalPowerAndVelocity`` at standstill);
the no-load speed is Kv x 24 V (mpat ``getVPerHz``: ``60 / Kv / sqrt(3)`` volts per Hz of
phase amplitude). All at the rotor: these motors are direct drive.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

SUPPLY = 24.0        # V: every controller's nominal (hardware.md), mpat's default
AMBIENT = 25.0       # °C: mpat's default ambient_temp


@dataclass(frozen=True)
class Controller:
    """One moteus controller board."""

    name: str
    min_voltage: float       # V
    max_voltage: float       # V: absolute maximum
    peak_current: float      # A: peak phase current


@dataclass(frozen=True)
class Motor:
    """One motor as mpat models it."""

    name: str
    kv: float                      # rpm/V
    resistance: float              # ohm, phase to the virtual centre
    poles: int
    inertia: float                 # kg·m², the rotor's
    max_temperature: float         # °C, the winding's
    thermal_resistance: float      # K/W, no cooling
    cutoff: float = math.inf       # A: rotationCurrentCutoff
    current_scale: float = 1.0     # rotationCurrentScale
    torque_scale: float = 1.0      # rotationTorqueScale (N·m)

    @property
    def torque_constant(self) -> float:
        """N·m/A (mpat: ``kt = 8.3 / Kv``)."""
        return 8.3 / self.kv

    @property
    def pole_pairs(self) -> int:
        return self.poles // 2

    def torque(self, current: float) -> float:
        """N·m at ``current`` A of q-axis current (mpat ``getRotorTorque``)."""
        if current < self.cutoff:
            return self.torque_constant * current
        return (self.torque_constant * self.cutoff + self.torque_scale
                * math.log2(1 + (current - self.cutoff) * self.current_scale))

    def continuous_current(self) -> float:
        """A: the copper loss the uncooled motor sheds at its maximum temperature."""
        watts = (self.max_temperature - AMBIENT) / self.thermal_resistance
        return math.sqrt(watts / 1.5 / self.resistance)


@dataclass(frozen=True)
class MoteusModel:
    """A motor on a controller: the figures of a drive (``Protocol.models``)."""

    motor: Motor
    controller: Controller

    @property
    def name(self) -> str:
        return self.motor.name

    @property
    def peak_torque(self) -> float:
        return self.motor.torque(self.controller.peak_current)

    @property
    def rated_torque(self) -> float:
        return self.motor.torque(min(self.motor.continuous_current(),
                                     self.controller.peak_current))

    @property
    def no_load_speed(self) -> float:
        """rad/s at ``SUPPLY``."""
        return self.motor.kv * SUPPLY / 60 * 2 * math.pi

    @property
    def reflected_inertia(self) -> float:
        return self.motor.inertia


CONTROLLERS = {c.name: c for c in (
    Controller("r4", 10.0, 44.0, 100.0),        # moteus-r4 (r4.11)
    Controller("c1", 10.0, 51.0, 20.0),
    Controller("n1", 10.0, 54.0, 100.0),
    Controller("x1", 10.0, 54.0, 120.0),
)}
MOTORS = {m.name: m for m in (
    Motor("mj5208", 304, 0.047, 14, 5.6e-5, 80, 4.55, 22.5, 0.02494, 0.6638),
    Motor("mad8318", 120, 0.0208, 42, 0.00603, 80, 1.516, 31.07, 0.004214, 12.087),
    Motor("be8108", 135, 0.0910, 42, 0.000110, 80, 2.74, 20.50, 0.04212, 1.0255),
)}
#: the controller a motor is sized on unless the options name another: the moteus-r4, the
#: controller of mjbots' developer kit with the mj5208
DEFAULT_CONTROLLER = "r4"
#: every motor on the default controller, by the motor's name (``hil init --motor mj5208``)
MODELS = {name: MoteusModel(motor, CONTROLLERS[DEFAULT_CONTROLLER])
          for name, motor in MOTORS.items()}


def find(table: dict, kind: str, name: str):
    """The entry of ``table`` named ``name`` (``moteus-r4``, ``r4.11`` and ``R4`` name the
    r4; ``MJ5208`` the mj5208); KeyError naming the known ones otherwise."""
    key = name.lower().removeprefix("moteus-").split(".")[0]
    if key not in table:
        raise KeyError(f"no moteus {kind} '{name}' (known: {', '.join(table)})")
    return table[key]
