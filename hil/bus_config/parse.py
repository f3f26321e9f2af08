"""Parsing a bus config file into :class:`~hil.bus_config.types.SystemConfig`: the whole
config (its robot, rates, ``base:`` and the keys each part reads), every key read once,
typed, with its line. A bus entry is read by :mod:`~hil.bus_config.bus_entry`, each of its
drives by :mod:`~hil.bus_config.drive_entry`."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from hil.bus_config.bus_entry import read_bus
from hil.bus_config.checks import check_system
from hil.bus_config.controllers_key import read_controllers
from hil.bus_config.drive_entry import DRIVE_KEYS
from hil.bus_config.joint_limits import apply_joint_limits
from hil.bus_config.scene import read_scene
from hil.bus_config.sensor_entry import read_sensors
from hil.bus_config.sensor_types import ForceTorqueConfig, Sensor
from hil.bus_config.start_pose import read_start_pose
from hil.bus_config.transmissions import add_transmissions
from hil.bus_config.types import SystemConfig
from hil.bus_config.yaml_reader import LineMapping, Reader, parse_yaml
from hil.description import PackagePath, load_description
from hil.errors import ConfigError, Severity
from hil.input_files import read_input_file
from hil.can.frame import FrameSpec
from hil.protocols import ati_netft, dm_imu, hipnuc
from hil.zenoh_session import key_name_problem
from hil.transmissions import build_transmissions

_TOP_KEYS = {"robot", "plant_rate_hz", "base", "start_pose", "defaults", "joint_limits",
             "transmissions", "buses", "scene", "controllers", "sensors"}
#: the ``base:`` values: the root link welded to the world, or free (a free joint)
BASES = {"fixed": False, "floating": True}


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
    reader.unknown_keys(defaults, DRIVE_KEYS - {"node_id", "joint", "actuator"}, "'defaults'")
    raw_buses = top.get("buses")
    if not isinstance(raw_buses, list) or not raw_buses:
        reader.fail("'buses' must be a non-empty list of buses", top.key_lines.get("buses", 1))
        raise ConfigError(reader.diagnostics)
    buses = tuple(read_bus(reader, raw, index, robot, transmissions, defaults)
                  for index, raw in enumerate(raw_buses))
    sensors = read_sensors(reader, top, robot, buses)
    buses = tuple(replace(bus, sensor_frames=tuple(
        spec for sensor in sensors if sensor.bus == bus.name
        for spec in sensor_frames(sensor))) for bus in buses)
    scene = read_scene(reader, top, robot)
    config = SystemConfig(path=path, robot=robot, plant_rate_hz=float(plant_rate), buses=buses,
                          scene=scene, floating_base=_read_base(reader, top),
                          start_pose=read_start_pose(reader, top, robot),
                          controllers=read_controllers(reader, top), sensors=sensors)
    check_system(reader, config, transmissions, top)
    errors = [d for d in reader.diagnostics if d.severity is Severity.ERROR]
    warnings = tuple(d for d in reader.diagnostics if d.severity is Severity.WARNING)
    if errors:
        raise ConfigError(errors + list(warnings))
    return replace(config, warnings=robot.warnings + warnings)


def sensor_frames(sensor: Sensor) -> list[FrameSpec]:
    """A CAN sensor's frames on its bus, named as the sensor's."""
    what = f"sensor '{sensor.name}'"
    if isinstance(sensor, ForceTorqueConfig):
        return ati_netft.frame_specs(sensor.base_id, sensor.poll_hz, what)
    if sensor.product == "dm_imu":
        return dm_imu.frame_specs(sensor.node_id, sensor.master_id, sensor.poll_hz,
                                  sensor.outputs, dm_imu.FIRMWARES[sensor.firmware], what)
    return hipnuc.frame_specs(sensor.node_id, sensor.rate_hz, sensor.outputs, what)


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


def _is_file(path: Path) -> bool:
    """Whether ``path`` is a file; False for a name the system cannot take (too long)."""
    try:
        return path.is_file()
    except OSError:
        return False
