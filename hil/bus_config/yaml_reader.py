"""YAML with line numbers, and typed reads from it that collect diagnostics (file, line,
what to do) instead of raising at the first problem.

PyYAML's nodes know their lines but its loaded mappings do not: :class:`LineLoader` keeps
them on each mapping."""

from __future__ import annotations

import math
from pathlib import Path

import yaml

from hil.errors import ConfigError, Diagnostic, did_you_mean, error, warning


class LineMapping(dict):
    """A YAML mapping that remembers the line of the mapping and of each key."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.line: int | None = None
        self.key_lines: dict[str, int] = {}


#: the most nodes a config may expand to with its aliases expanded (a 2 KB alias bomb
#: expands to billions, and printing one value of it took 1 GB), and its deepest nesting
MAX_NODES = 100_000
MAX_DEPTH = 100
#: a diagnostic quotes at most this much of a value
MAX_MESSAGE = 500


class ConfigTooLarge(yaml.YAMLError):
    """A YAML document whose aliases or nesting go beyond what a config needs."""

    def __init__(self, problem: str, mark):
        super().__init__(problem)
        self.problem, self.problem_mark = problem, mark


def _check_expansion(root) -> None:
    """ConfigTooLarge if the node graph under ``root``, aliases expanded, has more than
    MAX_NODES nodes or is nested deeper than MAX_DEPTH (counted once per node: no
    expansion is made)."""
    sizes: dict[int, int] = {}
    stack = [(root, 1, False)]
    while stack:
        node, depth, children_done = stack.pop()
        if depth > MAX_DEPTH:
            raise ConfigTooLarge(f"nested more than {MAX_DEPTH} deep", node.start_mark)
        if id(node) in sizes:
            continue
        children = ([item for pair in node.value for item in pair]
                    if isinstance(node, yaml.MappingNode) else
                    node.value if isinstance(node, yaml.SequenceNode) else [])
        if children_done or not children:
            sizes[id(node)] = 1 + sum(sizes[id(child)] for child in children)
            if sizes[id(node)] > MAX_NODES:
                raise ConfigTooLarge(f"its aliases expand it to over {MAX_NODES} values (an "
                                     "alias bomb?)", node.start_mark)
            continue
        stack.append((node, depth, True))
        stack.extend((child, depth + 1, False) for child in children
                     if id(child) not in sizes)


class LineLoader(yaml.SafeLoader):
    def compose_document(self):
        document = super().compose_document()
        _check_expansion(document)
        return document

    def construct_yaml_int(self, node):
        # PyYAML's int() of a scalar over 4300 digits raises a bare ValueError
        try:
            return super().construct_yaml_int(node)
        except ValueError:
            raise ConfigTooLarge(f"a number of {len(node.value)} characters is no value a "
                                 "config takes", node.start_mark) from None

    def construct_yaml_str(self, node):
        # a "\ud800" escape makes a str that is no text (half a UTF-16 surrogate pair):
        # MuJoCo's names and Python's encoders raise on it far from the config's line
        value = super().construct_yaml_str(node)
        if any("\ud800" <= c <= "\udfff" for c in value):
            raise yaml.constructor.ConstructorError(
                None, None, "a \\u escape of half a UTF-16 surrogate pair is no character: "
                "write the character itself", node.start_mark)
        return value

    def construct_mapping(self, node, deep=False):
        mapping = LineMapping(super().construct_mapping(node, deep=True))
        mapping.line = node.start_mark.line + 1
        mapping.key_lines = {k.value: k.start_mark.line + 1 for k, _ in node.value
                             if isinstance(k, yaml.ScalarNode)}
        return mapping


LineLoader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG,
                        LineLoader.construct_mapping)
LineLoader.add_constructor("tag:yaml.org,2002:int", LineLoader.construct_yaml_int)
LineLoader.add_constructor("tag:yaml.org,2002:str", LineLoader.construct_yaml_str)


def parse_yaml(text: str, path: Path, what: str):
    """The document of ``text`` (from ``path``, a ``what``: "a bus config", ...), mappings
    as LineMappings; ConfigError with the file and line for YAML it cannot take."""
    try:
        return yaml.load(text, Loader=LineLoader)
    except RecursionError:
        raise ConfigError.single("YAML nested too deeply to read", path,
                                 hint=f"{what} nests a few levels") from None
    except ConfigTooLarge as exc:
        raise ConfigError.single(f"YAML too large: {exc.problem}", path,
                                 exc.problem_mark.line + 1,
                                 hint=f"{what} is a few hundred small values: "
                                      "remove what is not one") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        raise ConfigError.single(f"YAML syntax: {getattr(exc, 'problem', exc)}", path,
                                 mark.line + 1 if mark else None,
                                 hint="fix the YAML at that line (indentation, ':' and "
                                      "'-')") from None


def _fits_a_float(value: int | float) -> bool:
    """Whether a YAML number is a finite float: an integer of 400 digits is not."""
    try:
        return math.isfinite(value)
    except OverflowError:
        return False


def _bounded(message: str) -> str:
    """A diagnostic's text, a value it quotes cut to MAX_MESSAGE characters."""
    return message if len(message) <= MAX_MESSAGE else \
        f"{message[:MAX_MESSAGE]}... ({len(message) - MAX_MESSAGE} more characters)"


class Reader:
    """Typed access to YAML mappings, collecting diagnostics with lines."""

    def __init__(self, path: Path):
        self.path = path
        self.diagnostics: list[Diagnostic] = []

    def fail(self, message: str, line: int | None, hint: str | None = None) -> None:
        self.diagnostics.append(error(_bounded(message), self.path, line, hint))

    def warn(self, message: str, line: int | None, hint: str | None = None) -> None:
        self.diagnostics.append(warning(_bounded(message), self.path, line, hint))

    def mapping(self, value, what: str, line: int | None) -> LineMapping:
        if isinstance(value, LineMapping):
            return value
        self.fail(f"{what} must be a mapping (key: value), not {type(value).__name__}", line)
        return LineMapping()

    def unknown_keys(self, mapping: LineMapping, known: set[str], what: str) -> None:
        for key in mapping:
            if key not in known:
                self.fail(f"unknown key '{key}' in {what}{did_you_mean(str(key), known)}",
                          mapping.key_lines.get(key, mapping.line),
                          hint=f"known keys: {', '.join(sorted(known))}")

    def number(self, mapping: LineMapping, key: str, what: str, default=None, *,
               positive: bool = True, integer: bool = False):
        line = mapping.key_lines.get(key, mapping.line)
        if key not in mapping:
            if default is None:
                self.fail(f"{what}: '{key}' is missing", mapping.line)
                return 1        # placeholder: the error above fails the load
            return default
        value = mapping[key]
        # What a failed value gives back: the error already fails the load, but the
        # parse goes on to find the file's other errors and must not crash on None.
        placeholder = 1 if default is None else default
        if isinstance(value, bool) or not isinstance(value, (int, float)) or (
                integer and not isinstance(value, int)):
            kind = "a whole number" if integer else "a number"
            self.fail(f"{what}: '{key}' must be {kind}, not {value!r}", line)
            return placeholder
        if not _fits_a_float(value) or (positive and value <= 0):
            self.fail(f"{what}: '{key}' must be {'> 0' if positive else 'finite'}, "
                      f"not {value}", line)
            return placeholder
        return value

    def text(self, mapping: LineMapping, key: str, what: str, default: str | None = None) -> str:
        value = mapping.get(key, default)
        if not isinstance(value, str) or not value:
            self.fail(f"{what}: '{key}' must be a non-empty string",
                      mapping.key_lines.get(key, mapping.line))
            return default or ""
        return value
