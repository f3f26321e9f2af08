"""A ROS 2 parameters file's node sections, and the parameters a node gets from them.

As rcl_yaml_param_parser reads the file: a node's parameters lie under
``<node>: ros__parameters:``, where ``<node>`` may be written with its namespace
(``/rrbot/controller_manager``), as nested keys (``rrbot: {controller_manager: ...}``) or with
wildcards (``/**`` any node, ``/**/name``, ``/*``); a value outside any ros__parameters is
refused ("Cannot have a value before ros__parameters"). As rclcpp applies it
(parameter_map.cpp, parameter_map_from): every section whose name matches the node, in the
file's order, a later value of a parameter replacing an earlier one.

hil runs one controller manager: a section's namespace is not compared, only its node name
(hil's choice; ``/rrbot_1/fwd`` and ``/rrbot_2/fwd`` are both ``fwd``)."""

from __future__ import annotations

from dataclasses import dataclass

from hil.bus_config.yaml_reader import LineMapping, Reader

PARAMETERS = "ros__parameters"
#: node names that match any node: ``/**`` and ``/*`` (rclcpp makes them regexes)
WILDCARDS = ("**", "*")


@dataclass(frozen=True)
class NodeSection:
    """One ``<node>: ros__parameters:`` of the file."""

    key: str                 # as the file writes it, nesting joined by "/": "/**", "rrbot/fwd"
    params: LineMapping
    line: int | None

    @property
    def name(self) -> str:
        """The node's name: the key's last part ("**" or "*" for a wildcard)."""
        return self.key.rstrip("/").rsplit("/", 1)[-1]

    @property
    def wildcard(self) -> bool:
        return self.name in WILDCARDS


def node_sections(reader: Reader, document: LineMapping) -> list[NodeSection]:
    """Every node section of the file in its order; a value outside any ros__parameters is
    reported (an error: ROS refuses the file)."""
    sections: list[NodeSection] = []
    _collect(reader, document, "", sections)
    return sections


def _collect(reader: Reader, mapping: LineMapping, prefix: str,
             sections: list[NodeSection]) -> None:
    for key, value in mapping.items():
        line = mapping.key_lines.get(key, mapping.line)
        where = f"{prefix}/{key}" if prefix else str(key)
        if key == PARAMETERS and prefix:
            continue                # the section itself, taken by the caller
        if not isinstance(value, LineMapping):
            outside = f"'{prefix}': '{key}'" if prefix else f"'{key}'"
            reader.fail(f"{outside} lies outside any ros__parameters: ROS refuses the file "
                        "(rcl_yaml_param_parser: \"Cannot have a value before "
                        "ros__parameters\")", line,
                        hint="a node's parameters go under <node>: ros__parameters:")
            continue
        if PARAMETERS in value:
            params = value[PARAMETERS]
            if params is None:          # an empty ros__parameters: sets nothing
                params = LineMapping()
            params = reader.mapping(params, f"'{where}: {PARAMETERS}'",
                                    value.key_lines.get(PARAMETERS, line))
            section = NodeSection(where, params, line)
            if section.name:
                sections.append(section)
            else:       # no node has an empty name (rmw_validate_node_name refuses it)
                reader.warn(f"'{where}' names no node: its ros__parameters go to none",
                            line, hint="write the node's name: <name>: ros__parameters:")
        _collect(reader, value, where, sections)


def named(sections: list[NodeSection]) -> list[str]:
    """The nodes the file names (no wildcard), each once, in the file's order."""
    return list(dict.fromkeys(s.name for s in sections if not s.wildcard))


def parameters_for(sections: list[NodeSection], node: str) -> LineMapping:
    """The parameters ``node`` gets: its sections' and the wildcards', merged in the file's
    order (nested mappings merged key by key, as ROS flattens them into dotted names). The
    merged mapping's line is that of the node's own section (None without one)."""
    merged = LineMapping()
    for section in sections:
        if section.name == node or section.wildcard:
            _merge(merged, section.params)
            if not section.wildcard and merged.line is None:
                merged.line = section.params.line
    return merged


def _merge(into: LineMapping, params: LineMapping) -> None:
    for key, value in params.items():
        line = params.key_lines.get(key, params.line)
        if isinstance(value, LineMapping):
            if not isinstance(into.get(key), LineMapping):
                into[key] = LineMapping()
                into[key].line = value.line
            _merge(into[key], value)        # copied: the sections stay as the file has them
        else:
            into[key] = value
        if line is not None:
            into.key_lines[key] = line
