"""A user's controller_manager YAML (ros2_controllers.yaml) read into the controllers hil
runs: the joint trajectory controller with its parameters, forward command controllers.

Read as ROS reads a parameters file (:mod:`hil.controllers.param_file`); the controllers
are the controller_manager's ``<controller>: {type: ...}`` entries and those whose own
``ros__parameters`` give their ``type`` (the spawner's ``--param-file`` layout).
What hil cannot honour in a controller it runs is an error naming the key and line;
controllers of types hil does not run, and parameters ROS would ignore (undeclared), are
warnings: the file loads unchanged. ``$(var NAME)`` is substituted from values the user
gives; no other launch substitution is evaluated (data never runs code)."""

from __future__ import annotations

import itertools
import re
from dataclasses import dataclass, replace
from pathlib import Path

from hil.bus_config.types import ControllersSource, SystemConfig
from hil.bus_config.yaml_reader import LineMapping, Reader, parse_yaml
from hil.controllers.forward import FORWARD_TYPES
from hil.controllers.jtc_section import read_jtc, read_joint_names
from hil.controllers.param_file import NodeSection, named, node_sections, parameters_for
from hil.controllers.parameters import COMMAND_INTERFACES, JointConstraint, JtcParameters
from hil.errors import ConfigError, Diagnostic, Severity, UsageError
from hil.input_files import read_input_file

#: rad (or m) each joint may end from a goal in hil's own controller set (hil control
#: --goal-tolerance)
DEFAULT_GOAL_TOLERANCE = 0.02
JTC_TYPE = "joint_trajectory_controller/JointTrajectoryController"
BROADCASTER = "joint_state_broadcaster/JointStateBroadcaster"
EFFORT_TYPE = "effort_controllers/JointGroupEffortController"
_SUBSTITUTION = re.compile(r"\$\((\w[\w-]*)([^)]*)\)")
#: distinct refused substitutions reported one by one: a file of more is no
#: ros2_controllers.yaml, and its report stays readable (hil's choice)
MAX_REFUSED_SUBSTITUTIONS = 20


@dataclass(frozen=True)
class ForwardSpec:
    name: str
    type: str
    joints: tuple[str, ...]
    interface: str


@dataclass(frozen=True)
class ControllersConfig:
    """The controllers a file gives hil to run, in the bench's joint names."""

    path: Path | None            # None: hil's own set (:func:`hil_controllers`)
    trajectory_name: str
    trajectory: JtcParameters
    forwards: tuple[ForwardSpec, ...]
    active: tuple[str, ...]
    warnings: tuple[Diagnostic, ...] = ()

    def summary(self) -> str:
        """Each controller by name, the active ones marked, in load order."""
        names = [self.trajectory_name, *(f.name for f in self.forwards)]
        return ", ".join(f"{name}{' (active)' if name in self.active else ''}"
                         for name in names)


def hil_controllers(joints: tuple[str, ...], goal_tolerance: float) -> ControllersConfig:
    """hil's own controllers where the bus config names no file, as a bringup's YAML would
    set them (docs/controllers.md shows it): the JTC over every joint, commanding position
    and velocity, partial goals allowed, each joint within ``goal_tolerance`` of its goal
    within 1 s of the last point, its end velocity not checked (a motor's residual motion
    is the drives' to judge); forward position and velocity controllers, inactive."""
    trajectory = JtcParameters(
        joints=joints, command_interfaces=COMMAND_INTERFACES,
        state_interfaces=("position", "velocity"), allow_partial_joints_goal=True,
        stopped_velocity_tolerance=0.0, goal_time=1.0,
        constraints={j: JointConstraint(goal=goal_tolerance) for j in joints})
    forwards = tuple(ForwardSpec(f"forward_{interface}_controller", type_name, joints,
                                 interface)
                     for type_name, interface in FORWARD_TYPES.items() if interface)
    return ControllersConfig(None, "joint_trajectory_controller", trajectory, forwards,
                             ("joint_trajectory_controller",))


def controllers_for(config: SystemConfig, goal_tolerance: float | None = None,
                    file: Path | None = None) -> ControllersConfig:
    """What the controller runs for a bus config: the controllers file ``file`` (with the
    config's ``controllers:`` names and values), else the config's own, else hil's set with
    ``goal_tolerance`` (None: DEFAULT_GOAL_TOLERANCE). UsageError where a file's constraints
    and ``goal_tolerance`` would both set the goal tolerance."""
    source = config.controllers
    if file is not None:
        source = replace(source, path=Path(file)) if source else ControllersSource(Path(file))
    driven = tuple(j.name for j in config.robot.driven_joints)
    if source is None:
        return hil_controllers(driven, goal_tolerance or DEFAULT_GOAL_TOLERANCE)
    if goal_tolerance is not None:
        raise UsageError.single("--goal-tolerance is for hil's own controllers: the "
                                f"controllers file {source.path} sets each joint's goal "
                                "tolerance (constraints: <joint>: goal)",
                                hint="leave out --goal-tolerance, or change the file")
    return load_controllers(source, driven, config.cycle_hz)


def load_controllers(source: ControllersSource, driven: tuple[str, ...],
                     cycle_hz: float) -> ControllersConfig:
    """Read ``source.path`` for a robot whose driven joints are ``driven``; ConfigError with
    every problem found (file, line, what to do)."""
    path = source.path
    text = read_input_file(path, "controllers file",
                           hint="give a controller_manager YAML (ros2_controllers.yaml)",
                           syntax="yaml")
    reader = Reader(path)
    text = _substitute(reader, text, dict(source.variables))
    _raise_errors(reader)
    document = reader.mapping(parse_yaml(text, path, "a controllers file"), "the file", 1)
    sections = node_sections(reader, document)
    types = _controller_types(reader, sections, cycle_hz)
    rename = dict(source.joint_names)
    joints = lambda names: tuple(rename.get(n, n) for n in names)  # noqa: E731
    trajectory_name, trajectory, forwards = None, None, []
    for name, (type_name, line) in types.items():
        params = parameters_for(sections, name)
        if type_name == JTC_TYPE and trajectory is None:
            trajectory_name = name
            trajectory = read_jtc(reader, params, name, joints, driven, line)
        elif type_name == JTC_TYPE:
            reader.warn(f"controller '{name}': hil runs one joint trajectory controller "
                        f"('{trajectory_name}'); this one is not loaded", line)
        elif type_name in FORWARD_TYPES or type_name == EFFORT_TYPE:
            spec = _forward(reader, name, type_name, params, joints, driven, line)
            if spec is not None:
                forwards.append(spec)
        elif type_name != BROADCASTER:
            reader.warn(f"controller '{name}' of type {type_name}: hil does not run this "
                        "type; it is not loaded", line,
                        hint="hil runs the joint trajectory controller and forward "
                             "position and velocity command controllers")
    if trajectory is None and types:
        first_line = next(iter(types.values()))[1]
        reader.fail("the file has no joint_trajectory_controller/JointTrajectoryController",
                    first_line, hint="hil's action server is a JTC's: add one")
    _raise_errors(reader)
    loaded = [trajectory_name, *(f.name for f in forwards)]
    active = source.active if source.active is not None else (trajectory_name,)
    for name in active:
        if name not in loaded:
            reader.fail(f"controllers: active: '{name}' is not a controller hil loaded from "
                        f"{path.name}", source.line, hint=f"loaded: {', '.join(loaded)}")
    _raise_errors(reader)
    return ControllersConfig(path, trajectory_name, trajectory, tuple(forwards), tuple(active),
                             tuple(reader.diagnostics))


def _raise_errors(reader: Reader) -> None:
    if any(d.severity is Severity.ERROR for d in reader.diagnostics):
        raise ConfigError(reader.diagnostics)


def _substitute(reader: Reader, text: str, variables: dict[str, str]) -> str:
    """``$(var NAME)`` replaced by the user's value; any other substitution refused (each
    distinct one reported once, at its first line; past MAX_REFUSED_SUBSTITUTIONS, one error
    counts the rest). Linear in the file's size: a line is found only for a reported
    substitution (issue 65 item 10: each scanned the text before it, and a million distinct
    ones fit the 16 MB a file may hold)."""
    refused: dict[str, int] = {}            # each distinct one, where it first stands

    def replace(match: re.Match) -> str:
        command, argument = match.group(1), match.group(2).strip()
        if command == "var" and argument in variables:
            return variables[argument]
        refused.setdefault(match.group(0), match.start())
        return match.group(0)
    substituted = _SUBSTITUTION.sub(replace, text)
    starts = iter(refused.items())
    for written, start in itertools.islice(starts, MAX_REFUSED_SUBSTITUTIONS):
        line = _line_at(text, start)
        command, argument = _SUBSTITUTION.fullmatch(written).groups()
        if command != "var":
            reader.fail(f"launch substitution {written!r}: hil substitutes only "
                        "$(var NAME), from values you give; nothing in the file is evaluated",
                        line, hint="write the value itself into the file")
        else:
            reader.fail(f"{written}: no value for '{argument.strip()}'", line,
                        hint=f"give it in the bus config: controllers: vars: "
                             f"{{{argument.strip()}: VALUE}}")
    if len(refused) > MAX_REFUSED_SUBSTITUTIONS:
        reader.fail(f"{len(refused) - MAX_REFUSED_SUBSTITUTIONS} more launch substitutions hil "
                    "cannot substitute", _line_at(text, next(starts)[1]),
                    hint="hil substitutes only $(var NAME), from controllers: vars; write "
                         "the other values themselves into the file")
    return substituted


def _line_at(text: str, index: int) -> int:
    return text.count("\n", 0, index) + 1


def _controller_types(reader: Reader, sections: list[NodeSection],
                      cycle_hz: float) -> dict[str, tuple[str, int | None]]:
    """Each controller's (type, line), in the file's order: those controller_manager lists
    (``<name>: {type: ...}``), then those whose own ros__parameters give a ``type``: the
    layout of the spawner's ``--param-file`` (controller_manager_services.py,
    set_controller_parameters_from_param_files: it sets ``<name>.type`` on the
    controller_manager from the controller's section, so that type wins)."""
    names = named(sections)
    types = {}
    if "controller_manager" in names:
        types = _manager_section(reader, parameters_for(sections, "controller_manager"),
                                 _own_keys(sections, "controller_manager"), cycle_hz)
    for name in names:
        params = parameters_for(sections, name)
        if name == "controller_manager":
            continue
        if "type" not in params:
            if name not in types:
                reader.warn(f"'{name}': controller_manager does not list it and its "
                            "ros__parameters give no type: not loaded",
                            _first_line(sections, name))
            continue
        type_name = reader.text(params, "type", f"controller '{name}'")
        line = params.key_lines.get("type", params.line)
        if name in types and types[name][0] != type_name:
            reader.warn(f"controller '{name}': its own type {type_name} replaces "
                        f"controller_manager's {types[name][0]}, as the spawner sets it", line)
        types[name] = (type_name, line)
    if not types:
        reader.fail("no controllers: no controller_manager: ros__parameters: <name>: "
                    "{type: ...} and no controller's own <name>: ros__parameters: "
                    "{type: ...}", 1, hint="a ros2_controllers.yaml lists its controllers "
                                           "either way (the spawner's --param-file layout)")
    return types


def _own_keys(sections: list[NodeSection], node: str) -> set[str]:
    """The parameters ``node``'s own sections set (not those a wildcard gives every node)."""
    return {key for s in sections if s.name == node for key in s.params}


def _first_line(sections: list[NodeSection], node: str) -> int | None:
    return next(s.line for s in sections if s.name == node)


def _manager_section(reader: Reader, manager: LineMapping, own: set[str],
                     cycle_hz: float) -> dict[str, tuple[str, int | None]]:
    """Each controller's (type, line) in the file's order; an update_rate other than the
    bus cycle, and other parameters of controller_manager's own sections, are warned
    about."""
    types = {}
    for key, value in manager.items():
        line = manager.key_lines.get(key, manager.line)
        if key == "update_rate":
            errors = len(reader.diagnostics)
            update_rate = reader.number(manager, key, "controller_manager")
            # a rate that is no number was reported; its placeholder says nothing
            if len(reader.diagnostics) == errors and update_rate != cycle_hz:
                reader.warn(f"controller_manager: update_rate {update_rate:g} Hz: hil's "
                            f"controllers run each bus cycle, at {cycle_hz:g} Hz", line,
                            hint="set the buses' cycle_hz to run them at this rate")
        elif isinstance(value, LineMapping) and "type" in value:
            types[key] = (reader.text(value, "type", f"controller '{key}'"), line)
        elif key in own:
            reader.warn(f"controller_manager parameter '{key}' is not used by hil", line)
    return types


def _forward(reader: Reader, name: str, type_name: str, params: LineMapping, joints,
             driven: tuple[str, ...], line: int | None) -> ForwardSpec | None:
    interface = ("effort" if type_name == EFFORT_TYPE else
                 FORWARD_TYPES[type_name] or params.get("interface_name"))
    if interface == "effort":
        reader.warn(f"controller '{name}' commands effort: hil's hardware interface exports "
                    "position and velocity command interfaces; it is not loaded", line)
        return None
    if interface not in ("position", "velocity"):
        reader.fail(f"controller '{name}': interface_name {interface!r} is not a command "
                    "interface of hil's hardware", params.key_lines.get("interface_name", line),
                    hint="position or velocity")
        return None
    mapped = read_joint_names(reader, params, f"controller '{name}'", joints, driven, line)
    return ForwardSpec(name, type_name, mapped, interface) if mapped else None
