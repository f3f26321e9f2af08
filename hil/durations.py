"""Durations as every command takes them: a number and a unit (``500ms``, ``2s``, ``10min``,
``1h``), a bare number in seconds; one syntax for every time option and the recording's
segment limit."""

from __future__ import annotations

import math
import re

#: seconds per unit; ``m`` is a minute, as ``--segment 10m`` has always read
UNITS = {"ms": 1e-3, "s": 1.0, "min": 60.0, "m": 60.0, "h": 3600.0}
_DURATION = re.compile(r"\s*([0-9]+(?:\.[0-9]*)?|\.[0-9]+)\s*([a-zA-Z]*)\s*")
#: how a duration is written, for help texts and errors
FORMS = "e.g. 500ms, 2s, 1.5, 10min, 1h (a bare number is seconds)"
#: the longest duration any option takes (s): a year, hil's choice (no bench run or wait is
#: longer). Far longer ones are no time a wait can take: Python's waits raise OverflowError
#: past threading.TIMEOUT_MAX (292 years), and Zenoh's liveliness get of 1e20 s raised
#: ValueError "negative timeout" (measured, eclipse-zenoh 1.10.2, 2026-12-06)
MAX_SECONDS = 365 * 24 * 3600.0


def parse_duration(text: str) -> float:
    """Seconds; ValueError saying the forms for anything else (a negative or unknown unit,
    NaN, infinity), or the bound for a duration over MAX_SECONDS."""
    match = _DURATION.fullmatch(text)
    unit = match.group(2).lower() if match else ""
    if match is None or (unit and unit not in UNITS):
        raise ValueError(f"{text!r} is not a duration: give {FORMS}")
    seconds = float(match.group(1)) * UNITS.get(unit, 1.0)
    if not math.isfinite(seconds):
        raise ValueError(f"{text!r} is not a finite duration")
    if seconds > MAX_SECONDS:
        raise ValueError(f"{text!r} is longer than a year, the longest duration hil takes")
    return seconds
