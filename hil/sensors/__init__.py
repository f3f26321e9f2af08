"""Simulated sensors, in the drives' wing: each fed by the plant, with its product's errors,
on its product's wire (docs/sensors.md).

:mod:`.noise` the errors of a sensing triad, :mod:`.imu` an IMU sampling the plant,
:mod:`.serial_port` the pseudo-terminal a serial sensor speaks on.
"""
