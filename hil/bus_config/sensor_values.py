"""The values a sensor entry of the bus config shares with every kind of sensor: a vector of
three numbers, and a triad's errors (:class:`~hil.bus_config.sensor_types.TriadErrors`)."""

from __future__ import annotations

import math

from hil.bus_config.sensor_types import ZERO, TriadErrors, Vector
from hil.bus_config.yaml_reader import LineMapping, Reader

ERROR_KEYS = {"noise_density", "bias_instability", "correlation_time", "random_walk", "bias",
              "scale_factor", "misalignment"}


def read_errors(reader: Reader, item: LineMapping, key: str, what: str,
                default: TriadErrors) -> TriadErrors:
    """The triad's errors under ``key`` (each left out: ``default``'s)."""
    if key not in item:
        return default
    errors = reader.mapping(item[key], f"{what}: '{key}'", item.key_lines.get(key, item.line))
    where = f"{what}: '{key}'"
    reader.unknown_keys(errors, ERROR_KEYS, where)
    numbers = {k: float(reader.number(errors, k, where, getattr(default, k), positive=False))
               for k in ("noise_density", "bias_instability", "random_walk")}
    for k, value in numbers.items():
        if value < 0:
            reader.fail(f"{where}: '{k}' must be >= 0, not {value:g}",
                        errors.key_lines.get(k, errors.line))
            numbers[k] = 0.0
    correlation = float(reader.number(errors, "correlation_time", where,
                                      default.correlation_time))
    return TriadErrors(**numbers, correlation_time=correlation,
                       bias=read_vector(reader, errors, "bias", where, math.inf),
                       scale_factor=read_vector(reader, errors, "scale_factor", where, 0.5),
                       misalignment=read_vector(reader, errors, "misalignment", where, 0.1))


def read_vector(reader: Reader, item: LineMapping, key: str, what: str,
                bound: float) -> Vector:
    """Three finite numbers within ±``bound`` under ``key`` (left out: zeros)."""
    value = item.get(key, list(ZERO))
    if (not isinstance(value, list) or len(value) != 3
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                       and math.isfinite(v) and abs(v) <= bound for v in value)):
        within = "" if math.isinf(bound) else f", each within ±{bound:g}"
        reader.fail(f"{what}: '{key}' must be three finite numbers{within}, not {value!r}",
                    item.key_lines.get(key, item.line))
        return ZERO
    return (float(value[0]), float(value[1]), float(value[2]))
