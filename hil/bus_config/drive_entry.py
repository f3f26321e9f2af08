"""One drive entry of a bus: its keys over the config's ``defaults:``, typed into a
:class:`~hil.bus_config.types.DriveConfig`, with defaults derived from the robot's limits
(or the product's own, where its protocol options name a motor model)."""

from __future__ import annotations

from hil.bus_config.drive_actuator import find_actuator, motor_limits
from hil.bus_config.drive_keys import (
    read_effects, read_gains, read_options, read_protocol, read_torque_feed_forward,
)
from hil.bus_config.types import DriveConfig
from hil.bus_config.yaml_reader import LineMapping, Reader
from hil.description import JointType, RobotDescription
from hil.transmissions import Transmission

DRIVE_KEYS = {"node_id", "joint", "actuator", "protocol", "encoder_counts_per_rev",
              "rated_torque", "peak_torque", "max_velocity", "following_error_limit",
              "following_error_timeout", "quick_stop_deceleration", "watchdog_timeout",
              "heartbeat_period", "holding_brake", "gains", "velocity_bandwidth_hz",
              "options", "effects", "torque_feed_forward"}
#: the default following-error window holds at least this long at the joint's top speed (s)
FOLLOWING_ERROR_TIME = 0.02


def read_drive(reader: Reader, raw, bus: str, robot: RobotDescription,
               transmissions: tuple[Transmission, ...], defaults: LineMapping) -> DriveConfig | None:
    own = reader.mapping(raw, f"{bus}: drive", None)
    reader.unknown_keys(own, DRIVE_KEYS, f"{bus} drive")
    merged = LineMapping({**defaults, **own})
    merged.line, merged.key_lines = own.line, {**defaults.key_lines, **own.key_lines}
    node_id = reader.number(merged, "node_id", f"{bus} drive", 0, integer=True, positive=False)
    what = f"{bus} node {node_id}"
    name = reader.text(merged, "protocol", what, "cia402")
    spec = read_protocol(reader, merged, what, name, node_id)
    if spec is None:
        return None
    options = read_options(reader, merged, what, spec)
    problem = spec.drive_problem(node_id, options)
    if problem:
        reader.fail(f"{what}: {problem}", merged.key_lines.get("node_id", merged.line))
    found = find_actuator(reader, merged, what, robot, transmissions)
    if found is None:
        return None
    transmission, k = found
    joint_limits = [robot.joint(j).limits for j in transmission.joints]
    motor_torque = transmission.actuator_effort_limits([lim.effort for lim in joint_limits])[k]
    motor_speed = abs(transmission.position_matrix[k]) @ [lim.velocity for lim in joint_limits]
    product = options.drive_defaults() if options is not None else {}   # a motor model's
    peak = reader.number(merged, "peak_torque", what,
                         product.get("peak_torque", float(motor_torque)))
    rated = reader.number(merged, "rated_torque", what, product.get("rated_torque", peak / 2))
    if peak < rated:
        reader.fail(f"{what}: peak_torque {peak} is below rated_torque {rated}",
                    merged.key_lines.get("peak_torque", merged.line))
    max_velocity = reader.number(merged, "max_velocity", what,
                                 product.get("max_velocity", float(motor_speed)))
    # default following-error window at the joint: 0.1 rad (revolute) or 5 mm (prismatic),
    # or FOLLOWING_ERROR_TIME at the joint's top speed where that is more (a fast axis lags
    # its setpoint by a bus cycle and its loops' delay)
    joint_window = [max(0.005 if robot.joint(j).type is JointType.PRISMATIC else 0.1,
                        FOLLOWING_ERROR_TIME * robot.joint(j).limits.velocity)
                    for j in transmission.joints]
    window = float(abs(transmission.position_matrix[k]) @ joint_window)
    gains = read_gains(reader, merged, what)
    brake = merged.get("holding_brake", product.get("holding_brake", True))
    if not isinstance(brake, bool):
        reader.fail(f"{what}: holding_brake must be true or false",
                    merged.key_lines.get("holding_brake", merged.line))
    config = DriveConfig(
        node_id=node_id, actuator=transmission.actuators[k], joints=transmission.joints,
        protocol=name,
        encoder_counts_per_rev=int(reader.number(merged, "encoder_counts_per_rev", what, 131072,
                                                 integer=True)),
        rated_torque=float(rated), peak_torque=float(peak), max_velocity=float(max_velocity),
        following_error_limit=float(reader.number(merged, "following_error_limit", what,
                                                  window)),
        following_error_timeout=float(reader.number(merged, "following_error_timeout", what,
                                                    0.01)),
        quick_stop_deceleration=float(reader.number(merged, "quick_stop_deceleration", what,
                                                    max_velocity / 0.1)),
        watchdog_timeout=_watchdog_timeout(reader, merged, what, product),
        heartbeat_period=float(reader.number(merged, "heartbeat_period", what, 0.1)),
        holding_brake=bool(brake),
        position_limits=motor_limits(robot, transmission),
        gains=gains,
        velocity_bandwidth_hz=float(reader.number(merged, "velocity_bandwidth_hz", what, 40.0)),
        options=options, line=own.line, effects=read_effects(reader, merged, what),
        torque_feed_forward=read_torque_feed_forward(reader, merged, what, spec))
    _check_setting_fields(reader, merged, what, spec, config)
    return config


def _check_setting_fields(reader: Reader, merged: LineMapping, what: str, spec,
                          config: DriveConfig) -> None:
    """Refuse a setting the product's own field cannot hold (hil sim could not encode it)."""
    for name, field in spec.setting_fields.items():
        value = getattr(config, name)
        if not field.holds(value):
            reader.fail(f"{what}: '{name}' {value:.12g} does not fit the drive's {field.field}",
                        merged.key_lines.get(name, merged.line),
                        hint=f"{spec.name} takes {field.low / field.scale:.12g} to "
                             f"{field.high / field.scale:.12g} there")



def _watchdog_timeout(reader: Reader, drive: LineMapping, what: str, product: dict) -> float:
    """``watchdog_timeout`` (s; 0: off), by default the product's, else 0.1."""
    value = float(reader.number(drive, "watchdog_timeout", what,
                                product.get("watchdog_timeout", 0.1), positive=False))
    if value < 0:
        reader.fail(f"{what}: 'watchdog_timeout' must be >= 0 (0: no watchdog), not {value:g}",
                    drive.key_lines.get("watchdog_timeout", drive.line))
    return value
