"""Simulated sensors, in the drives' wing: each fed by the plant, with its product's errors,
on its product's wire (docs/sensors.md).

:mod:`.noise` the errors of a sensing triad, :mod:`.imu` an IMU sampling the plant,
:mod:`.port` where its samples go: :mod:`.serial_port` the pseudo-terminal a serial sensor
speaks on, :mod:`.can_port` a CANopen IMU's node, :mod:`.polled_port` a DM-IMU answering
requests; :mod:`.force_torque` a Net F/T answering its master.
"""
