"""A drive entry's own sub-keys, each read with its line: ``protocol`` (and the node id's
range), ``options`` (the protocol's settings), ``gains``, ``effects`` and
``torque_feed_forward``."""

from __future__ import annotations

from hil.bus_config.types import NO_EFFECTS, ActuatorEffects, Gains
from hil.bus_config.yaml_reader import LineMapping, Reader
from hil.errors import did_you_mean
from hil.protocols import names as protocol_names
from hil.protocols import protocol

#: what a master may add to each setpoint as torque feed-forward (``torque_feed_forward``)
TORQUE_FEED_FORWARD = ("none", "gravity")
_GAIN_KEYS = {"position_kp", "velocity_kp", "velocity_ki"}


def read_torque_feed_forward(reader: Reader, drive: LineMapping, what: str, spec) -> str:
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


def read_protocol(reader: Reader, drive: LineMapping, what: str, name: str, node_id: int):
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


def read_gains(reader: Reader, drive: LineMapping, what: str) -> Gains | None:
    """The drive's ``gains:`` (None: tuned by the simulator)."""
    if "gains" not in drive:
        return None
    gains = reader.mapping(drive["gains"], f"{what} gains", drive.key_lines.get("gains"))
    reader.unknown_keys(gains, _GAIN_KEYS, f"{what} gains")
    return Gains(*(reader.number(gains, key, f"{what} gains", 1.0) for key in
                   ("position_kp", "velocity_kp", "velocity_ki")))


def read_effects(reader: Reader, drive: LineMapping, what: str) -> ActuatorEffects:
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


def read_options(reader: Reader, drive: LineMapping, what: str, spec) -> object | None:
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

