"""The velocity unit of a CiA 402 drive's objects: what one unit/s of 0x6080, 0x607F, 0x6081,
0x60FF, 0x60B1, 0x6099 and 0x606C (and, per second, of the accelerations) is at the motor.

CiA 402 gives velocities in user position units per second (the factor group: feed constant
0x6092 / gear ratio 0x6091 per shaft revolution) unless the drive's SI unit velocity
0x60A9 says otherwise: its bits 24-31 a power of ten (signed), bits 16-23 the position unit,
bits 8-15 the time unit (CiA 402's SI unit objects, as the makers' manuals give them:
Nanotec's 0x60A9 "bits 8 to 15: the time unit, bits 16 to 23: the position unit, bits 24 to
31: the exponent of a power of ten", default 0x00B44700; Synapticon's 0x60A9 rpm
0x00B44700, 0.001 rpm 0xFDB44700). A revolution, degree or radian there is the shaft's (the
factor group's gear ratio to the motor); a position unit hil does not know, or a file
without 0x60A9 (hil's own EDS), keeps the factor group's position units per second.
Accelerations are in the velocity unit per second (CiA 402's default; Synapticon: rpm/s
beside rpm); hil does not read 0x60AA.
"""

from __future__ import annotations

import math

#: position unit codes of 0x60A8/0x60A9 (CiA 303-2's table as CiA 402 uses it) -> the unit in
#: shaft revolutions
REVOLUTION, DEGREE, RADIAN = 0xB4, 0x41, 0x10
SHAFT_REVOLUTIONS = {REVOLUTION: 1.0, DEGREE: 1 / 360, RADIAN: 1 / (2 * math.pi)}
#: time unit codes -> seconds
SECONDS = {0x03: 1.0, 0x47: 60.0, 0x48: 3600.0}
SI_UNIT_VELOCITY = 0x60A9


def velocity_per_rad(unit: int | None, counts_per_rad: float, gear: float) -> float:
    """Velocity units per motor rad/s. ``unit``: 0x60A9 (None where the file has none);
    ``counts_per_rad``: position units per motor radian (the factor group); ``gear``: motor
    revolutions per shaft revolution (0x6091)."""
    if not unit:
        return counts_per_rad
    exponent = (unit >> 24 & 0xFF) - (0x100 if unit >> 31 else 0)
    position, time = unit >> 16 & 0xFF, unit >> 8 & 0xFF
    if position not in SHAFT_REVOLUTIONS or time not in SECONDS:
        return counts_per_rad
    # one motor radian is 1 / (2 pi gear) shaft revolutions
    units_per_rad = 1 / (2 * math.pi * gear) / SHAFT_REVOLUTIONS[position]
    return units_per_rad * SECONDS[time] / 10.0 ** exponent
