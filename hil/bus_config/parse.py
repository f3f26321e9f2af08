"""Parsing a bus config file into :class:`~hil.bus_config.types.SystemConfig`: every key
read once, typed, with defaults derived from the robot's limits."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from hil.bus_config.checks import check_system
from hil.bus_config.controllers_key import read_controllers
from hil.bus_config.joint_limits import apply_joint_limits
from hil.bus_config.scene import read_scene
from hil.bus_config.start_pose import read_start_pose
from hil.bus_config.transmissions import add_transmissions
from hil.bus_config.types import (
    NO_EFFECTS, ActuatorEffects, BusConfig, DriveConfig, Gains, SystemConfig,
)
from hil.bus_config.yaml_reader import LineMapping, Reader, parse_yaml
from hil.description import JointType, PackagePath, RobotDescription, load_description
from hil.errors import ConfigError, Severity, did_you_mean
from hil.input_files import read_input_file
from hil.zenoh_session import key_name_problem
from hil.protocols import names as protocol_names
from hil.protocols import protocol
from hil.transmissions import SimpleTransmission, Transmission, build_transmissions

_TOP_KEYS = {"robot", "plant_rate_hz", "base", "start_pose", "defaults", "joint_limits",
             "transmissions", "buses", "scene", "controllers"}
#: the ``base:`` values: the root link welded to the world, or free (a free joint)
BASES = {"fixed": False, "floating": True}
_BUS_KEYS = {"name", "interface", "channel", "bitrate", "cycle_hz", "drives"}
_DRIVE_KEYS = {"node_id", "joint", "actuator", "protocol", "encoder_counts_per_rev",
               "rated_torque", "peak_torque", "max_velocity", "following_error_limit",
               "following_error_timeout", "quick_stop_deceleration", "watchdog_timeout",
               "heartbeat_period", "holding_brake", "gains", "velocity_bandwidth_hz",
               "options", "effects", "torque_feed_forward"}
#: what a master may add to each setpoint as torque feed-forward (``torque_feed_forward``)
TORQUE_FEED_FORWARD = ("none", "gravity")
_GAIN_KEYS = {"position_kp", "velocity_kp", "velocity_ki"}
#: the default following-error window holds at least this long at the joint's top speed (s)
FOLLOWING_ERROR_TIME = 0.02


def load_bus_config(path: str | Path, package_path: PackagePath | None = None) -> SystemConfig:
    """Parse and validate a bus config and the robot it names.

    Raises :class:`ConfigError` with every error found (warnings travel along).
    """
    path = Path(path)
    text = read_input_file(path, "bus config", hint="give the path of a bus_config/*.yaml file",
                           syntax="yaml")
    document = parse_yaml(text, path, "a bus config")
    reader = Reader(path)
    top = reader.mapping(document, "the bus config", 1)
    reader.unknown_keys(top, _TOP_KEYS, "the bus config")
    robot_path = path.parent / reader.text(top, "robot", "the bus config", "")
    if not _is_file(robot_path):
        reader.fail(f"robot description '{robot_path}' does not exist",
                    top.key_lines.get("robot", 1),
                    hint="'robot' is a .xacro/.urdf path relative to the config file")
        raise ConfigError(reader.diagnostics)
    robot = load_description(robot_path, package_path)
    problem = key_name_problem(robot.name)
    if problem:
        raise ConfigError.single(f"robot name {robot.name!r}: {problem}", robot_path,
                                 hint="name the robot with letters, digits, '_', '-' or '.' "
                                      "(<robot name=\"...\">): its keys are hil/<name>/...")
    robot = add_transmissions(reader, top, apply_joint_limits(reader, top, robot))
    if any(d.severity is Severity.ERROR for d in reader.diagnostics):
        raise ConfigError(reader.diagnostics + list(robot.warnings))
    transmissions = build_transmissions(robot)
    plant_rate = reader.number(top, "plant_rate_hz", "the bus config", 1000.0)
    defaults = reader.mapping(top.get("defaults", LineMapping()), "'defaults'",
                              top.key_lines.get("defaults"))
    reader.unknown_keys(defaults, _DRIVE_KEYS - {"node_id", "joint", "actuator"}, "'defaults'")
    raw_buses = top.get("buses")
    if not isinstance(raw_buses, list) or not raw_buses:
        reader.fail("'buses' must be a non-empty list of buses", top.key_lines.get("buses", 1))
        raise ConfigError(reader.diagnostics)
    buses = tuple(_read_bus(reader, raw, index, robot, transmissions, defaults)
                  for index, raw in enumerate(raw_buses))
    scene = read_scene(reader, top, robot)
    config = SystemConfig(path=path, robot=robot, plant_rate_hz=float(plant_rate), buses=buses,
                          scene=scene, floating_base=_read_base(reader, top),
                          start_pose=read_start_pose(reader, top, robot),
                          controllers=read_controllers(reader, top))
    check_system(reader, config, transmissions, top)
    errors = [d for d in reader.diagnostics if d.severity is Severity.ERROR]
    warnings = tuple(d for d in reader.diagnostics if d.severity is Severity.WARNING)
    if errors:
        raise ConfigError(errors + list(warnings))
    return replace(config, warnings=robot.warnings + warnings)


def _read_base(reader: Reader, top: LineMapping) -> bool:
    """``base:`` fixed (the default) or floating."""
    base = top.get("base", "fixed")
    if not isinstance(base, str) or base not in BASES:
        reader.fail(f"'base' must be {' or '.join(BASES)}, not {base!r}",
                    top.key_lines.get("base", top.line),
                    hint="floating: the robot's root is free and stands on the scene (a legged "
                         "or mobile robot); fixed: it is welded to the world (an arm)")
        return False
    return BASES[base]


def _read_bus(reader: Reader, raw, index: int, robot: RobotDescription,
              transmissions: tuple[Transmission, ...], defaults: LineMapping) -> BusConfig:
    bus = reader.mapping(raw, f"bus {index + 1}", None)
    reader.unknown_keys(bus, _BUS_KEYS, f"bus {index + 1}")
    name = reader.text(bus, "name", f"bus {index + 1}", f"bus{index + 1}")
    what = f"bus '{name}'"
    raw_drives = bus.get("drives")
    if not isinstance(raw_drives, list) or not raw_drives:
        reader.fail(f"{what}: 'drives' must be a non-empty list", bus.key_lines.get("drives",
                                                                                    bus.line))
        raw_drives = []
    drives = tuple(d for d in (_read_drive(reader, raw_drive, what, robot, transmissions,
                                           defaults) for raw_drive in raw_drives) if d)
    return BusConfig(
        name=name,
        interface=reader.text(bus, "interface", what, "zenoh"),
        channel=_channel(reader, bus, what, f"{robot.name}/{name}"),
        bitrate=int(reader.number(bus, "bitrate", what, 1_000_000, integer=True)),
        cycle_hz=float(reader.number(bus, "cycle_hz", what)),
        drives=drives, line=bus.line)


def _read_drive(reader: Reader, raw, bus: str, robot: RobotDescription,
                transmissions: tuple[Transmission, ...], defaults: LineMapping) -> DriveConfig | None:
    own = reader.mapping(raw, f"{bus}: drive", None)
    reader.unknown_keys(own, _DRIVE_KEYS, f"{bus} drive")
    merged = LineMapping({**defaults, **own})
    merged.line, merged.key_lines = own.line, {**defaults.key_lines, **own.key_lines}
    node_id = reader.number(merged, "node_id", f"{bus} drive", 0, integer=True, positive=False)
    what = f"{bus} node {node_id}"
    name = reader.text(merged, "protocol", what, "cia402")
    spec = _read_protocol(reader, merged, what, name, node_id)
    if spec is None:
        return None
    options = _read_options(reader, merged, what, spec)
    problem = spec.drive_problem(node_id, options)
    if problem:
        reader.fail(f"{what}: {problem}", merged.key_lines.get("node_id", merged.line))
    found = _find_actuator(reader, merged, what, robot, transmissions)
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
    gains = _read_gains(reader, merged, what)
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
        position_limits=_motor_limits(robot, transmission),
        gains=gains,
        velocity_bandwidth_hz=float(reader.number(merged, "velocity_bandwidth_hz", what, 40.0)),
        options=options, line=own.line, effects=_read_effects(reader, merged, what),
        torque_feed_forward=_read_torque_feed_forward(reader, merged, what, spec))
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


def _is_file(path: Path) -> bool:
    """Whether ``path`` is a file; False for a name the system cannot take (too long)."""
    try:
        return path.is_file()
    except OSError:
        return False


def _channel(reader: Reader, bus: LineMapping, what: str, default: str) -> str:
    """The bus' channel: a key expression's chunks on the ``zenoh`` interface, so no
    wildcards (``hil/can/<channel>``)."""
    channel = reader.text(bus, "channel", what, default)
    problem = key_name_problem(channel, slashes=True)
    if problem:
        reader.fail(f"{what}: channel {channel!r}: {problem}",
                    bus.key_lines.get("channel", bus.line),
                    hint="e.g. channel: ur3/arm (or vcan0 for SocketCAN)")
    return channel


def _watchdog_timeout(reader: Reader, drive: LineMapping, what: str, product: dict) -> float:
    """``watchdog_timeout`` (s; 0: off), by default the product's, else 0.1."""
    value = float(reader.number(drive, "watchdog_timeout", what,
                                product.get("watchdog_timeout", 0.1), positive=False))
    if value < 0:
        reader.fail(f"{what}: 'watchdog_timeout' must be >= 0 (0: no watchdog), not {value:g}",
                    drive.key_lines.get("watchdog_timeout", drive.line))
    return value


def _read_torque_feed_forward(reader: Reader, drive: LineMapping, what: str, spec) -> str:
    value = drive.get("torque_feed_forward", "none")
    line = drive.key_lines.get("torque_feed_forward", drive.line)
    if value not in TORQUE_FEED_FORWARD:
        reader.fail(f"{what}: torque_feed_forward is one of {', '.join(TORQUE_FEED_FORWARD)}, "
                    f"not {value!r}", line,
                    hint="gravity: the master adds the torque that holds the joints against "
                         "gravity, from the description")
        return "none"
    if value != "none" and not spec.carries_torque_feed_forward:
        reader.fail(f"{what}: protocol '{spec.name}' has no torque feed-forward", line,
                    hint="leave torque_feed_forward out for this drive")
        return "none"
    return value


def _read_protocol(reader: Reader, drive: LineMapping, what: str, name: str, node_id: int):
    """The drive's protocol (None, reported, if none is registered under ``name``); a node
    id outside the protocol's range is reported."""
    if name not in protocol_names():
        reader.fail(f"{what}: unknown protocol '{name}'{did_you_mean(name, protocol_names())}",
                    drive.key_lines.get("protocol", drive.line),
                    hint=f"use one of: {', '.join(protocol_names())}")
        return None
    spec = protocol(name)
    if node_id not in spec.node_ids and node_id != spec.unconfigured_node_id:
        ids = spec.node_ids
        reader.fail(f"{what}: node id {node_id} is outside {ids.start}..{ids.stop - 1}",
                    drive.key_lines.get("node_id", drive.line),
                    hint=f"{name} node ids are {ids.start}..{ids.stop - 1}")
    return spec


def _read_gains(reader: Reader, drive: LineMapping, what: str) -> Gains | None:
    """The drive's ``gains:`` (None: tuned by the simulator)."""
    if "gains" not in drive:
        return None
    gains = reader.mapping(drive["gains"], f"{what} gains", drive.key_lines.get("gains"))
    reader.unknown_keys(gains, _GAIN_KEYS, f"{what} gains")
    return Gains(*(reader.number(gains, key, f"{what} gains", 1.0) for key in
                   ("position_kp", "velocity_kp", "velocity_ki")))


def _read_effects(reader: Reader, drive: LineMapping, what: str) -> ActuatorEffects:
    """The drive's ``effects:`` (none set: the perfect motor and gear)."""
    if "effects" not in drive:
        return NO_EFFECTS
    effects = reader.mapping(drive["effects"], f"{what} effects", drive.key_lines.get("effects"))
    reader.unknown_keys(effects, set(ActuatorEffects.KEYS), f"{what} effects")
    values = []
    for key in ActuatorEffects.KEYS:
        value = float(reader.number(effects, key, f"{what} effects", 0.0, positive=False))
        if value < 0:
            reader.fail(f"{what} effects: '{key}' must be >= 0 (0: off), not {value:g}",
                        effects.key_lines.get(key, effects.line))
            value = 0.0
        values.append(value)
    return ActuatorEffects(*values)


def _read_options(reader: Reader, drive: LineMapping, what: str, spec) -> object | None:
    """The protocol's own settings (``options:``), validated by its ``Options``."""
    raw = drive.get("options", LineMapping())
    line = drive.key_lines.get("options", drive.line)
    if spec.Options is None:
        if raw:
            reader.fail(f"{what}: protocol '{spec.name}' takes no 'options'", line)
        return None
    if not isinstance(raw, dict):
        reader.fail(f"{what}: 'options' must be a mapping", line)
        return None
    unknown = sorted(set(raw) - set(spec.Options.KEYS))
    if unknown:
        reader.fail(f"{what}: unknown option(s) {', '.join(unknown)} for protocol "
                    f"'{spec.name}'", line,
                    hint=f"{spec.name} options: {', '.join(spec.Options.KEYS)}")
        return None
    values = dict(raw)
    for key in spec.Options.PATH_KEYS:
        if isinstance(values.get(key), str):
            values[key] = str(reader.path.parent / values[key])
    try:
        return spec.Options.from_mapping(values)
    except (ValueError, TypeError, OverflowError) as exc:     # Overflow: a 400-digit int
        reader.fail(f"{what}: options: {exc}", line,
                    hint=f"{spec.name} options: {', '.join(spec.Options.KEYS)}")
        return None


def _find_actuator(reader: Reader, drive: LineMapping, what: str, robot: RobotDescription,
                   transmissions: tuple[Transmission, ...]) -> tuple[Transmission, int] | None:
    line = drive.key_lines.get("joint", drive.key_lines.get("actuator", drive.line))
    for name_key in ("actuator", "joint"):
        if name_key in drive and not isinstance(drive[name_key], str):
            reader.fail(f"{what}: '{name_key}' must be a name, not {drive[name_key]!r}", line)
            return None
    if "actuator" in drive:
        for transmission in transmissions:
            if drive["actuator"] in transmission.actuators:
                return transmission, transmission.actuators.index(drive["actuator"])
        reader.fail(f"{what}: actuator '{drive['actuator']}' is not in robot '{robot.name}'",
                    line, hint=f"actuators: {', '.join(a.name for a in robot.actuators)}")
        return None
    joint = drive.get("joint")
    if joint is None:
        reader.fail(f"{what}: give the 'joint' (or 'actuator') this drive moves", drive.line)
        return None
    for transmission in transmissions:
        if joint in transmission.joints:
            if len(transmission.actuators) > 1:
                reader.fail(f"{what}: joint '{joint}' is driven by several actuators "
                            f"({', '.join(transmission.actuators)})", line,
                            hint="name the 'actuator' instead of the joint")
                return None
            return transmission, 0
    driven = ", ".join(j.name for j in robot.driven_joints)
    known = joint in {j.name for j in robot.joints}
    near = "" if known else did_you_mean(joint, (j.name for j in robot.driven_joints))
    reader.fail(f"{what}: joint '{joint}' " + ("has no transmission in" if known else
                                               "does not exist in") + f" robot '{robot.name}'"
                + near, line, hint=f"driven joints: {driven}")
    return None


def _motor_limits(robot: RobotDescription, transmission: Transmission) -> tuple[float, float] | None:
    """Software position limits on the motor, from the joint limits (simple transmissions)."""
    if not isinstance(transmission, SimpleTransmission):
        return None
    joint = robot.joint(transmission.joints[0])
    if joint.type is JointType.CONTINUOUS or joint.limits is None or joint.limits.lower is None:
        return None
    ends = sorted(float(transmission.joint_to_actuator_position([q])[0])
                  for q in (joint.limits.lower, joint.limits.upper))
    return ends[0], ends[1]
