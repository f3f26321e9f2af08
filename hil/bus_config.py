"""Bus configs (``bus_config/*.yaml``): parsed once into typed objects.

A bus config names a robot description, the plant rate, and one or more CAN
buses, each with its python-can interface/channel, bitrate, cycle rate and
drives. Every problem is reported with the config file and line and what to
do, and the whole config is checked against the robot (joints, actuators,
node ids) and against the physics of the bus (worst-case load).

Drive quantities are motor side, SI units (rad, rad/s, N·m), as the drive
itself sees them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import can
import yaml

from hil.can import BusLoad, bus_load, open_bus
from hil.description import JointType, PackagePath, RobotDescription, load_description
from hil.protocols import names as protocol_names
from hil.protocols import protocol
from hil.errors import Diagnostic, HilError, Severity, error, warning
from hil.transmissions import SimpleTransmission, Transmission, build_transmissions
from hil.zenoh_session import ZenohSettings

#: Bus load above which a bus has no room left for SDO, EMCY, heartbeats and retries.
LOAD_WARNING = 0.8
HEARTBEAT_PAYLOAD = 1
SYNC_PAYLOAD = 0


@dataclass(frozen=True)
class Gains:
    position_kp: float      # 1/s
    velocity_kp: float      # N·m·s/rad
    velocity_ki: float      # N·m/rad


@dataclass(frozen=True)
class DriveConfig:
    """One drive on a bus; ``gains`` None means tuned from the plant's inertia."""

    node_id: int
    actuator: str
    joints: tuple[str, ...]
    protocol: str
    encoder_counts_per_rev: int
    rated_torque: float
    peak_torque: float
    max_velocity: float
    following_error_limit: float
    following_error_timeout: float
    quick_stop_deceleration: float
    watchdog_timeout: float
    heartbeat_period: float
    holding_brake: bool
    position_limits: tuple[float, float] | None
    gains: Gains | None
    velocity_bandwidth_hz: float
    options: object | None = None     # the protocol's own settings (its profile's Options)
    line: int | None = None

    @property
    def label(self) -> str:
        return f"node {self.node_id} ({', '.join(self.joints)})"


@dataclass(frozen=True)
class BusConfig:
    name: str
    interface: str
    channel: str
    bitrate: int
    cycle_hz: float
    drives: tuple[DriveConfig, ...]
    line: int | None = None

    @property
    def cycle(self) -> float:
        return 1.0 / self.cycle_hz

    @property
    def uses_sync(self) -> bool:
        return any(protocol(d.protocol).uses_sync for d in self.drives)

    def frames(self, drive: DriveConfig) -> list[tuple[int, int, float]]:
        """(id, payload bytes, frames/s) of one drive's traffic, as its profile says."""
        return protocol(drive.protocol).bus_frames(drive.node_id, self.cycle_hz,
                                                   drive.heartbeat_period, drive.options)

    def load(self) -> BusLoad:
        """Worst-case traffic of every drive's cyclic exchange and timed messages (each
        profile's own frames and lengths), plus SYNC where a CANopen drive needs it."""
        streams = [(SYNC_PAYLOAD, self.cycle_hz)] if self.uses_sync else []
        for drive in self.drives:
            streams += [(payload, rate) for _, payload, rate in self.frames(drive) if rate > 0]
        return bus_load(self.bitrate, streams)


@dataclass(frozen=True)
class SystemConfig:
    """A whole bench: robot, plant rate, buses."""

    path: Path
    robot: RobotDescription
    plant_rate_hz: float
    buses: tuple[BusConfig, ...]
    warnings: tuple[Diagnostic, ...] = field(default=(), compare=False)

    @property
    def cycle_hz(self) -> float:
        return self.buses[0].cycle_hz

    @property
    def drives(self) -> tuple[DriveConfig, ...]:
        return tuple(d for bus in self.buses for d in bus.drives)

    @property
    def steps_per_cycle(self) -> int:
        return round(self.plant_rate_hz / self.cycle_hz)


# --- YAML with line numbers ---------------------------------------------------

class _Mapping(dict):
    """A YAML mapping that remembers the line of the mapping and of each key."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.line: int | None = None
        self.key_lines: dict[str, int] = {}


class _Loader(yaml.SafeLoader):
    def construct_mapping(self, node, deep=False):
        mapping = _Mapping(super().construct_mapping(node, deep=True))
        mapping.line = node.start_mark.line + 1
        mapping.key_lines = {k.value: k.start_mark.line + 1 for k, _ in node.value
                             if isinstance(k, yaml.ScalarNode)}
        return mapping


_Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG,
                        _Loader.construct_mapping)


class _Reader:
    """Typed access to YAML mappings, collecting diagnostics with lines."""

    def __init__(self, path: Path):
        self.path = path
        self.diagnostics: list[Diagnostic] = []

    def fail(self, message: str, line: int | None, hint: str | None = None) -> None:
        self.diagnostics.append(error(message, self.path, line, hint))

    def warn(self, message: str, line: int | None, hint: str | None = None) -> None:
        self.diagnostics.append(warning(message, self.path, line, hint))

    def mapping(self, value, what: str, line: int | None) -> _Mapping:
        if isinstance(value, _Mapping):
            return value
        self.fail(f"{what} must be a mapping (key: value), not {type(value).__name__}", line)
        return _Mapping()

    def unknown_keys(self, mapping: _Mapping, known: set[str], what: str) -> None:
        for key in mapping:
            if key not in known:
                self.fail(f"unknown key '{key}' in {what}",
                          mapping.key_lines.get(key, mapping.line),
                          hint=f"known keys: {', '.join(sorted(known))}")

    def number(self, mapping: _Mapping, key: str, what: str, default=None, *,
               positive: bool = True, integer: bool = False):
        line = mapping.key_lines.get(key, mapping.line)
        if key not in mapping:
            if default is None:
                self.fail(f"{what}: '{key}' is missing", mapping.line)
                return 1        # placeholder: the error above fails the load
            return default
        value = mapping[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or (
                integer and not isinstance(value, int)):
            kind = "a whole number" if integer else "a number"
            self.fail(f"{what}: '{key}' must be {kind}, not {value!r}", line)
            return default
        if not math.isfinite(value) or (positive and value <= 0):
            self.fail(f"{what}: '{key}' must be {'> 0' if positive else 'finite'}, not {value}",
                      line)
            return default
        return value

    def text(self, mapping: _Mapping, key: str, what: str, default: str | None = None) -> str:
        value = mapping.get(key, default)
        if not isinstance(value, str) or not value:
            self.fail(f"{what}: '{key}' must be a non-empty string",
                      mapping.key_lines.get(key, mapping.line))
            return default or ""
        return value


# --- parsing ------------------------------------------------------------------

_TOP_KEYS = {"robot", "plant_rate_hz", "defaults", "buses"}
_BUS_KEYS = {"name", "interface", "channel", "bitrate", "cycle_hz", "drives"}
_DRIVE_KEYS = {"node_id", "joint", "actuator", "protocol", "encoder_counts_per_rev",
               "rated_torque", "peak_torque", "max_velocity", "following_error_limit",
               "following_error_timeout", "quick_stop_deceleration", "watchdog_timeout",
               "heartbeat_period", "holding_brake", "gains", "velocity_bandwidth_hz",
               "options"}
_GAIN_KEYS = {"position_kp", "velocity_kp", "velocity_ki"}


def load_bus_config(path: str | Path, package_path: PackagePath | None = None) -> SystemConfig:
    """Parse and validate a bus config and the robot it names.

    Raises :class:`HilError` with every error found (warnings travel along).
    """
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise HilError.single(f"cannot read bus config '{path}': {exc.strerror}",
                              hint="give the path of a bus_config/*.yaml file") from None
    try:
        document = yaml.load(text, Loader=_Loader)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        raise HilError.single(f"YAML syntax: {getattr(exc, 'problem', exc)}", path,
                              mark.line + 1 if mark else None,
                              hint="fix the YAML at that line (indentation, ':' and '-')") from None
    reader = _Reader(path)
    top = reader.mapping(document, "the bus config", 1)
    reader.unknown_keys(top, _TOP_KEYS, "the bus config")
    robot_path = path.parent / reader.text(top, "robot", "the bus config", "")
    if not robot_path.is_file():
        reader.fail(f"robot description '{robot_path}' does not exist",
                    top.key_lines.get("robot", 1),
                    hint="'robot' is a .xacro/.urdf path relative to the config file")
        raise HilError(reader.diagnostics)
    robot = load_description(robot_path, package_path)
    transmissions = build_transmissions(robot)
    plant_rate = reader.number(top, "plant_rate_hz", "the bus config", 1000.0)
    defaults = reader.mapping(top.get("defaults", _Mapping()), "'defaults'",
                              top.key_lines.get("defaults"))
    reader.unknown_keys(defaults, _DRIVE_KEYS - {"node_id", "joint", "actuator"}, "'defaults'")
    raw_buses = top.get("buses")
    if not isinstance(raw_buses, list) or not raw_buses:
        reader.fail("'buses' must be a non-empty list of buses", top.key_lines.get("buses", 1))
        raise HilError(reader.diagnostics)
    buses = tuple(_read_bus(reader, raw, index, robot, transmissions, defaults)
                  for index, raw in enumerate(raw_buses))
    config = SystemConfig(path=path, robot=robot, plant_rate_hz=float(plant_rate), buses=buses)
    _check_system(reader, config, transmissions, top)
    errors = [d for d in reader.diagnostics if d.severity is Severity.ERROR]
    warnings = tuple(d for d in reader.diagnostics if d.severity is Severity.WARNING)
    if errors:
        raise HilError(errors + list(warnings))
    return SystemConfig(path=path, robot=robot, plant_rate_hz=float(plant_rate), buses=buses,
                        warnings=robot.warnings + warnings)


def _read_bus(reader: _Reader, raw, index: int, robot: RobotDescription,
              transmissions: tuple[Transmission, ...], defaults: _Mapping) -> BusConfig:
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
        channel=reader.text(bus, "channel", what, f"{robot.name}/{name}"),
        bitrate=int(reader.number(bus, "bitrate", what, 1_000_000, integer=True)),
        cycle_hz=float(reader.number(bus, "cycle_hz", what)),
        drives=drives, line=bus.line)


def _read_drive(reader: _Reader, raw, bus: str, robot: RobotDescription,
                transmissions: tuple[Transmission, ...], defaults: _Mapping) -> DriveConfig | None:
    own = reader.mapping(raw, f"{bus}: drive", None)
    reader.unknown_keys(own, _DRIVE_KEYS, f"{bus} drive")
    merged = _Mapping({**defaults, **own})
    merged.line, merged.key_lines = own.line, {**defaults.key_lines, **own.key_lines}
    node_id = reader.number(merged, "node_id", f"{bus} drive", 0, integer=True, positive=False)
    what = f"{bus} node {node_id}"
    name = reader.text(merged, "protocol", what, "cia402")
    if name not in protocol_names():
        reader.fail(f"{what}: unknown protocol '{name}'",
                    merged.key_lines.get("protocol", merged.line),
                    hint=f"use one of: {', '.join(protocol_names())}")
        return None
    spec = protocol(name)
    if node_id not in spec.node_ids:
        ids = spec.node_ids
        reader.fail(f"{what}: node id {node_id} is outside {ids.start}..{ids.stop - 1}",
                    merged.key_lines.get("node_id", merged.line),
                    hint=f"{name} node ids are {ids.start}..{ids.stop - 1}")
    options = _read_options(reader, merged, what, spec)
    found = _find_actuator(reader, merged, what, robot, transmissions)
    if found is None:
        return None
    transmission, k = found
    joint_limits = [robot.joint(j).limits for j in transmission.joints]
    motor_torque = transmission.actuator_effort_limits([lim.effort for lim in joint_limits])[k]
    motor_speed = abs(transmission.position_matrix[k]) @ [lim.velocity for lim in joint_limits]
    peak = reader.number(merged, "peak_torque", what, float(motor_torque))
    rated = reader.number(merged, "rated_torque", what, peak / 2)
    if peak < rated:
        reader.fail(f"{what}: peak_torque {peak} is below rated_torque {rated}",
                    merged.key_lines.get("peak_torque", merged.line))
    max_velocity = reader.number(merged, "max_velocity", what, float(motor_speed))
    # default following-error window: 0.1 rad (revolute) or 5 mm (prismatic) at the joint
    joint_window = [0.005 if robot.joint(j).type is JointType.PRISMATIC else 0.1
                    for j in transmission.joints]
    window = float(abs(transmission.position_matrix[k]) @ joint_window)
    gains = None
    if "gains" in merged:
        g = reader.mapping(merged["gains"], f"{what} gains", merged.key_lines.get("gains"))
        reader.unknown_keys(g, _GAIN_KEYS, f"{what} gains")
        gains = Gains(*(reader.number(g, key, f"{what} gains", 1.0) for key in
                        ("position_kp", "velocity_kp", "velocity_ki")))
    brake = merged.get("holding_brake", True)
    if not isinstance(brake, bool):
        reader.fail(f"{what}: holding_brake must be true or false",
                    merged.key_lines.get("holding_brake", merged.line))
    return DriveConfig(
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
        watchdog_timeout=float(reader.number(merged, "watchdog_timeout", what, 0.1)),
        heartbeat_period=float(reader.number(merged, "heartbeat_period", what, 0.1)),
        holding_brake=bool(brake),
        position_limits=_motor_limits(robot, transmission),
        gains=gains,
        velocity_bandwidth_hz=float(reader.number(merged, "velocity_bandwidth_hz", what, 40.0)),
        options=options, line=own.line)


def _read_options(reader: _Reader, drive: _Mapping, what: str, spec) -> object | None:
    """The protocol's own settings (``options:``), validated by its ``Options``."""
    raw = drive.get("options", _Mapping())
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
    try:
        return spec.Options.from_mapping(dict(raw))
    except (ValueError, TypeError) as exc:
        reader.fail(f"{what}: options: {exc}", line,
                    hint=f"{spec.name} options: {', '.join(spec.Options.KEYS)}")
        return None


def _find_actuator(reader: _Reader, drive: _Mapping, what: str, robot: RobotDescription,
                   transmissions: tuple[Transmission, ...]) -> tuple[Transmission, int] | None:
    line = drive.key_lines.get("joint", drive.key_lines.get("actuator", drive.line))
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
    reader.fail(f"{what}: joint '{joint}' " + ("has no transmission in" if known else
                                               "does not exist in") + f" robot '{robot.name}'",
                line, hint=f"driven joints: {driven}")
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


def _check_system(reader: _Reader, config: SystemConfig, transmissions, top: _Mapping) -> None:
    names = [bus.name for bus in config.buses]
    for bus in config.buses:
        if names.count(bus.name) > 1:
            reader.fail(f"bus name '{bus.name}' is used twice", bus.line)
        seen: dict[tuple[str, int], DriveConfig] = {}     # node ids are per protocol
        for drive in bus.drives:
            key = (drive.protocol, drive.node_id)
            if key in seen:
                reader.fail(f"bus '{bus.name}': node id {drive.node_id} is used by "
                            f"{seen[key].label} (line {seen[key].line}) and "
                            f"{drive.label}", drive.line, hint="give every drive on a bus its own node id")
            seen[key] = drive
        _check_ids(reader, bus)
        ratio = config.plant_rate_hz / bus.cycle_hz
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            reader.fail(f"bus '{bus.name}': cycle_hz {bus.cycle_hz:g} does not divide "
                        f"plant_rate_hz {config.plant_rate_hz:g}", bus.line,
                        hint="the plant steps a whole number of times per control cycle")
        _check_load(reader, bus)
    rates = {bus.cycle_hz for bus in config.buses}
    if len(rates) > 1:
        reader.fail(f"buses have different cycle rates ({', '.join(f'{r:g}' for r in sorted(rates))}"
                    " Hz)", top.key_lines.get("buses"),
                    hint="one controller cycle drives all buses: give them one cycle_hz")
    by_actuator: dict[str, list[DriveConfig]] = {}
    for drive in config.drives:
        by_actuator.setdefault(drive.actuator, []).append(drive)
    for actuator, drives in by_actuator.items():
        if len(drives) > 1:
            reader.fail(f"actuator '{actuator}' has {len(drives)} drives "
                        f"({'; '.join(d.label for d in drives)})", drives[1].line)
    for transmission in transmissions:
        for actuator in transmission.actuators:
            if actuator not in by_actuator:
                reader.fail(f"actuator '{actuator}' (joint {', '.join(transmission.joints)}) "
                            "has no drive", top.key_lines.get("buses"),
                            hint="add a drive for it to one of the buses")


def _check_ids(reader: _Reader, bus: BusConfig) -> None:
    """Two drives (of any protocols) must not use the same CAN id on one bus."""
    owners: dict[int, str] = {}
    if bus.uses_sync:
        owners.update({0x000: "CANopen NMT", 0x080: "CANopen SYNC"})
    shared: dict[int, str] = {}
    for drive in bus.drives:
        spec = protocol(drive.protocol)
        label = f"{drive.label} ({drive.protocol})"
        for can_id in sorted({frame[0] for frame in bus.frames(drive)}):
            if can_id in spec.shared_ids(drive.options) and shared.get(can_id) == drive.protocol:
                continue
            if can_id in owners:
                reader.fail(f"bus '{bus.name}': CAN id 0x{can_id:03X} is used by {owners[can_id]} "
                            f"and by {label}", drive.line,
                            hint="change a node id (or a protocol option such as reply_id), or "
                                 "put the drives on separate buses")
                continue
            owners[can_id] = label
            if can_id in spec.shared_ids(drive.options):
                shared[can_id] = drive.protocol


def _check_load(reader: _Reader, bus: BusConfig) -> None:
    if not bus.drives or any(d.protocol not in protocol_names() for d in bus.drives):
        return
    load = bus.load()
    summary = (f"bus '{bus.name}': {len(bus.drives)} drive(s) at {bus.cycle_hz:g} Hz need "
               f"{load.worst_bits_per_second / 1e3:,.0f} kbit/s worst case "
               f"({load.nominal_bits_per_second / 1e3:,.0f} nominal, "
               f"{load.frames_per_second:,.0f} frames/s) on a {bus.bitrate / 1e3:,.0f} kbit/s bus: "
               f"{load.worst_ratio:.0%}")
    sync_bits = bus_load(bus.bitrate, [(SYNC_PAYLOAD, bus.cycle_hz)]).worst_bits_per_second
    per_drive = (load.worst_bits_per_second - sync_bits) / len(bus.drives)
    budget = LOAD_WARNING * bus.bitrate
    fitting_drives = max(int((budget - sync_bits) // per_drive), 1)
    fitting_rate = budget / (load.worst_bits_per_second / bus.cycle_hz)
    hint = (f"split the drives over buses of at most {fitting_drives} drive(s) each, or lower "
            f"cycle_hz to {fitting_rate:,.0f} Hz or less (either keeps the load under "
            f"{LOAD_WARNING:.0%})")
    if load.worst_ratio > 1.0:
        reader.fail(f"{summary}: infeasible", bus.line, hint=hint)
    elif load.worst_ratio > LOAD_WARNING:
        reader.warn(f"{summary}: above {LOAD_WARNING:.0%}, no room for SDO, EMCY and retries",
                    bus.line, hint=hint)


def open_buses(config: SystemConfig, zenoh: ZenohSettings, interface: str | None = None,
               channels: dict[str, str] | None = None) -> dict[str, can.BusABC]:
    """Open every bus of a config, with optional interface/channel overrides.

    Zenoh buses join the process' Zenoh session given by ``zenoh``.
    """
    channels = channels or {}
    unknown = set(channels) - {bus.name for bus in config.buses}
    if unknown:
        raise HilError.single(f"--channel names unknown bus(es) {', '.join(sorted(unknown))}",
                              config.path,
                              hint=f"buses: {', '.join(bus.name for bus in config.buses)}")
    opened: dict[str, can.BusABC] = {}
    try:
        for bus in config.buses:
            name = interface or bus.interface
            options = ({"listen": zenoh.listen, "connect": zenoh.connect,
                        "zenoh_config": zenoh.config_file} if name == "zenoh" else {})
            opened[bus.name] = open_bus(name, channels.get(bus.name, bus.channel), bus.bitrate,
                                        **options)
    except HilError:
        for bus in opened.values():
            bus.shutdown()
        raise
    return opened
