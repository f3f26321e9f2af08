"""Classic CAN frame sizes and bus load.

A data frame with an 11-bit identifier and n data bytes has 47 + 8n bits
before stuffing; worst-case bit stuffing adds floor((34 + 8n - 1) / 4)
bits (29-bit identifiers: 67 + 8n and floor((54 + 8n - 1) / 4)).
"""

from __future__ import annotations

from dataclasses import dataclass


def frame_bits(payload: int, extended: bool = False) -> tuple[int, int]:
    """(nominal, worst-case stuffed) bits on the wire, interframe space included."""
    if not 0 <= payload <= 8:
        raise ValueError(f"classic CAN carries 0..8 data bytes, not {payload}")
    overhead, stuffable = (67, 54) if extended else (47, 34)
    nominal = overhead + 8 * payload
    return nominal, nominal + (stuffable + 8 * payload - 1) // 4


@dataclass(frozen=True)
class BusLoad:
    """Traffic of one bus against its bitrate."""

    frames_per_second: float
    nominal_bits_per_second: float
    worst_bits_per_second: float
    bitrate: int

    @property
    def worst_ratio(self) -> float:
        return self.worst_bits_per_second / self.bitrate

    @property
    def nominal_ratio(self) -> float:
        return self.nominal_bits_per_second / self.bitrate


def bus_load(bitrate: int, streams: list[tuple]) -> BusLoad:
    """Load of ``streams`` = [(payload bytes, frames per second[, extended id]), ...]."""
    frames = nominal = worst = 0.0
    for payload, rate, *kind in streams:
        bits = frame_bits(payload, bool(kind and kind[0]))
        frames += rate
        nominal += bits[0] * rate
        worst += bits[1] * rate
    return BusLoad(frames, nominal, worst, bitrate)
