"""A joint_trajectory_controller's ``ros__parameters`` read into :class:`JtcParameters`,
key by key as the JTC declares them (jazzy: src/joint_trajectory_controller_parameters.yaml).

A value hil cannot honour is an error naming its line; a key the JTC does not declare is a
warning (ROS ignores undeclared parameters); one the JTC declares but that changes nothing
on hil's hardware (gains without a velocity- or effort-only interface, speed scaling
interfaces hil's hardware lacks) is a warning saying so."""

from __future__ import annotations

from collections.abc import Callable

from hil.bus_config.yaml_reader import LineMapping, Reader
from hil.controllers.parameters import JointConstraint, JtcParameters

#: the JTC's, and hil's own reject_unreachable_first_point (a real JTC ignores it, as it
#: ignores any undeclared parameter)
_BOOLS = ("allow_partial_joints_goal", "allow_nonzero_velocity_at_trajectory_end",
          "interpolate_from_desired_state", "allow_integration_in_goal_trajectories",
          "reject_unreachable_first_point")
#: each number's least value: action_monitor_rate as the JTC validates it (gt_eq: [0.1]; hil
#: took any rate > 0, and one of 5e-324 Hz made the control node's feedback period, in
#: cycles, infinite); cmd_timeout, which the JTC leaves unvalidated, >= 0 (hil's choice: a
#: negative timeout means nothing)
_NUMBERS = {"action_monitor_rate": 0.1, "cmd_timeout": 0.0}
#: declared by the JTC; hil honours them only at these values
_FIXED = {"interpolation_method": "splines",
          "set_last_command_interface_value_as_state_on_activation": True}
#: ``type``: the controller's type, where its own section gives it (the spawner's
#: --param-file layout)
_KNOWN = {"type", "joints", "command_joints", "command_interfaces", "state_interfaces", "gains",
          "constraints", "speed_scaling", "open_loop_control", *_BOOLS, *_NUMBERS, *_FIXED}
_COMMANDS = (("position",), ("position", "velocity"))


def read_jtc(reader: Reader, params: LineMapping, name: str,
             rename: Callable[[list[str]], tuple[str, ...]],
             driven: tuple[str, ...], declared: int | None = None) -> JtcParameters:
    """The controller ``name``'s parameters (joints renamed onto the bench's); problems
    go to ``reader`` with their lines (a parameter the file does not give: its section's,
    else ``declared``, where the controller is declared)."""
    what = f"controller '{name}'"
    line = lambda key: params.key_lines.get(key, params.line or declared)  # noqa: E731
    for key in params:
        if key not in _KNOWN:
            reader.warn(f"{what}: '{key}' is not a parameter of the joint_trajectory_controller"
                        " (jazzy): ignored, as ROS ignores undeclared parameters", line(key))
    joints = read_joint_names(reader, params, what, rename, driven, declared)
    command_joints = _names(reader, params, "command_joints", what, "joint names")
    if command_joints and rename(list(command_joints)) != joints:
        reader.fail(f"{what}: command_joints differ from joints: hil's JTC commands the "
                    "joints it tracks", line("command_joints"))
    commands = _names(reader, params, "command_interfaces", what, "interface names")
    if commands is not None and commands not in _COMMANDS:
        reader.fail(f"{what}: command_interfaces {list(commands)}: hil's hardware takes "
                    "[position] or [position, velocity]", line("command_interfaces"),
                    hint="its drives run cyclic synchronous position")
    states = _names(reader, params, "state_interfaces", what, "interface names")
    # the JTC declares it unique<> (joint_trajectory_controller_parameters.yaml)
    if states is not None and ("position" not in states or len(set(states)) < len(states)
                               or not set(states) <= {"position", "velocity"}):
        reader.fail(f"{what}: state_interfaces {list(states)}: hil's hardware gives "
                    "[position] or [position, velocity]", line("state_interfaces"))
    values = {key: _bool(reader, params, key, what) for key in _BOOLS if key in params}
    if params.get("open_loop_control") is True:     # the JTC takes it as the next one
        values["interpolate_from_desired_state"] = True
    for key, least in _NUMBERS.items():
        if key in params:
            values[key] = float(reader.number(params, key, what, positive=False))
            if values[key] < least:
                reader.fail(f"{what}: {key} must be >= {least:g}, not {values[key]:g}",
                            line(key))
    for key, honoured in _FIXED.items():
        if key in params and params[key] != honoured:
            reader.fail(f"{what}: {key} {params[key]!r}: hil runs the JTC with {honoured!r}",
                        line(key))
    _notes(reader, params, what, commands or ())
    constraints = reader.mapping(params.get("constraints", LineMapping()),
                                 f"{what}: constraints", line("constraints"))
    return JtcParameters(joints=joints, command_interfaces=commands or ("position",),
                         state_interfaces=states or ("position",),
                         **values, **_constraints(reader, constraints, what, rename, joints))


def read_joint_names(reader: Reader, params: LineMapping, what: str,
                     rename: Callable[[list[str]], tuple[str, ...]], driven: tuple[str, ...],
                     line: int | None = None) -> tuple[str, ...]:
    """A controller's ``joints``, renamed onto the bench's; () after reporting a list that is
    empty or not of names, a joint that is not driven, or one named twice (at the key's line,
    else the section's, else ``line``)."""
    key = "joints"
    names = params.get(key)
    at = params.key_lines.get(key, params.line or line)
    if not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
        reader.fail(f"{what}: '{key}' must be a non-empty list of joint names", at)
        return ()
    mapped = rename(names)
    for original, joint in zip(names, mapped):
        if joint not in driven:
            reader.fail(f"{what}: joint '{original}' is not a driven joint of the robot", at,
                        hint=f"driven joints: {', '.join(driven)}; map others with "
                             "controllers: joint_names in the bus config")
    if len(set(mapped)) != len(mapped):
        reader.fail(f"{what}: a joint is named twice in '{key}'", at)
    return mapped


def _names(reader: Reader, params: LineMapping, key: str, what: str,
           kind: str) -> tuple[str, ...] | None:
    """A string_array parameter (the JTC declares these so): its names, () where it is not
    given, None after reporting a value that is no list of names."""
    value = params.get(key, [])
    if not isinstance(value, list) or not all(isinstance(n, str) and n for n in value):
        reader.fail(f"{what}: '{key}' must be a list of {kind}, not {value!r}",
                    params.key_lines.get(key, params.line))
        return None
    return tuple(value)


def _bool(reader: Reader, params: LineMapping, key: str, what: str) -> bool:
    value = params[key]
    if not isinstance(value, bool):
        reader.fail(f"{what}: {key} must be true or false, not {value!r}",
                    params.key_lines.get(key))
        return False
    return value


def _notes(reader: Reader, params: LineMapping, what: str, commands: tuple[str, ...]) -> None:
    """Parameters the JTC declares that change nothing on hil's hardware."""
    if "gains" in params:
        reader.warn(f"{what}: gains: the JTC closes a loop with them only for a velocity- or "
                    f"effort-only command interface; with {list(commands)} it ignores them, "
                    "and so does hil", params.key_lines.get("gains"))
    scaling = params.get("speed_scaling")
    if isinstance(scaling, LineMapping):
        if scaling.get("initial_scaling_factor", 1.0) != 1.0:
            reader.fail(f"{what}: speed_scaling: initial_scaling_factor: hil runs "
                        "trajectories at 1.0", scaling.key_lines.get("initial_scaling_factor"))
        for key in ("state_interface", "command_interface"):
            if scaling.get(key):
                reader.warn(f"{what}: speed_scaling: {key} '{scaling[key]}': hil's hardware "
                            "exports no speed-scaling interface; trajectories run at 1.0",
                            scaling.key_lines.get(key))


def _constraints(reader: Reader, constraints: LineMapping, what: str, rename,
                 joints: tuple[str, ...]) -> dict:
    values: dict = {}
    per_joint: dict[str, JointConstraint] = {}
    for key, value in constraints.items():
        at = constraints.key_lines.get(key, constraints.line)
        if key in ("stopped_velocity_tolerance", "goal_time"):
            values[key] = float(reader.number(constraints, key, f"{what}: constraints",
                                              positive=False))
            if values[key] < 0:
                reader.fail(f"{what}: constraints: {key} must be >= 0", at)
        elif key == "decelerate_on_cancel":
            values[key] = _bool(reader, constraints, key, f"{what}: constraints")
        elif rename([key])[0] in joints:
            per_joint[rename([key])[0]] = _joint_constraint(
                reader, reader.mapping(value, f"{what}: constraints: {key}", at),
                f"{what}: constraints: {key}")
        else:
            reader.warn(f"{what}: constraints: '{key}' is neither a parameter nor one of the "
                        "controller's joints: ignored, as ROS ignores it", at)
    values["constraints"] = per_joint
    return values


def _joint_constraint(reader: Reader, entry: LineMapping, what: str) -> JointConstraint:
    numbers = {}
    for key in entry:
        if key not in JointConstraint.__dataclass_fields__:
            reader.warn(f"{what}: '{key}' is not a constraint of the JTC: ignored",
                        entry.key_lines.get(key))
            continue
        numbers[key] = float(reader.number(entry, key, what, positive=False))
        if numbers[key] < 0:
            reader.fail(f"{what}: {key} must be >= 0", entry.key_lines.get(key))
    return JointConstraint(**numbers)
