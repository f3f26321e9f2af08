"""Frame sizes on the wire and bus load, classic CAN and CAN FD.

Classic CAN (ISO 11898-1): a data frame with an 11-bit identifier and n data bytes has
47 + 8n bits before stuffing; worst-case bit stuffing adds floor((34 + 8n - 1) / 4) bits
(29-bit identifiers: 67 + 8n and floor((54 + 8n - 1) / 4)).

CAN FD (ISO 11898-1:2015, 10.4): the arbitration phase (SOF to BRS: 17 bits, 36 with a
29-bit identifier) and the end (CRC delimiter, ACK, EOF, intermission: 13 bits) run at the
nominal bit rate; ESI, DLC, the data, the stuff count (4 bits) and the CRC (17 bits up to
16 data bytes, 21 above) run at the data bit rate where the frame switches (BRS), with a
fixed stuff bit before the stuff count and after every 4 bits of it and the CRC. Dynamic
stuffing from SOF to the data's end is counted at worst, one bit per 4, each part at its
own phase's rate. Bits are counted in nominal bit times: a data-phase bit at a data bit
rate k times the nominal one counts 1/k.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from typing import NamedTuple

from hil.can.frame import CLASSIC_MAX_LENGTH, FD_LENGTHS, FrameSpec


def frame_bits(payload: int, extended: bool = False) -> tuple[int, int]:
    """(nominal, worst-case stuffed) bits of a classic frame on the wire, interframe space
    included."""
    if not 0 <= payload <= CLASSIC_MAX_LENGTH:
        raise ValueError(f"classic CAN carries 0..8 data bytes, not {payload}")
    overhead, stuffable = (67, 54) if extended else (47, 34)
    nominal = overhead + 8 * payload
    return nominal, nominal + (stuffable + 8 * payload - 1) // 4


def fd_frame_bits(payload: int, extended: bool = False, rate_ratio: float = 1.0
                  ) -> tuple[float, float]:
    """(without dynamic stuffing, worst-case stuffed) nominal bit times of a CAN FD data
    frame whose data phase runs ``rate_ratio`` times the nominal bit rate (1: no bit-rate
    switch); the fixed stuff bits count in both."""
    if payload not in FD_LENGTHS:
        raise ValueError(f"CAN FD carries one of {FD_LENGTHS} data bytes, not {payload}")
    arbitration = 36 if extended else 17
    crc = 17 if payload <= 16 else 21
    data_phase = 1 + 4 + 8 * payload + 4 + crc
    fixed_stuff = 1 + (4 + crc) // 4
    end = 13
    dynamic_nominal = (arbitration - 1) // 4
    dynamic_data = (5 + 8 * payload) // 4
    # the fixed stuff bits are in every frame, the dynamic ones at worst
    unstuffed = arbitration + end + (data_phase + fixed_stuff) / rate_ratio
    worst = unstuffed + dynamic_nominal + dynamic_data / rate_ratio
    return unstuffed, worst


class BitRates(NamedTuple):
    """A bus' bit rates (bit/s): its nominal one, and CAN FD's data phase where frames
    switch to it (None on a classical bus)."""

    nominal: int
    data: int | None = None

    def data_ratio(self, bitrate_switch: bool) -> float:
        """How many times faster than the nominal rate a frame's data phase runs."""
        return (self.data or self.nominal) / self.nominal if bitrate_switch else 1.0


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


def spec_bits(spec: FrameSpec, bitrate: int, data_bitrate: int | None = None
              ) -> tuple[float, float]:
    """(unstuffed, worst-case stuffed) nominal bit times of one frame of ``spec`` on a bus
    of ``bitrate`` (and ``data_bitrate`` for CAN FD's switched data phase)."""
    if not spec.fd:
        return frame_bits(spec.length, spec.extended)
    return fd_frame_bits(spec.length, spec.extended,
                         BitRates(bitrate, data_bitrate).data_ratio(spec.bitrate_switch))


def bus_load(bitrate: int, specs: Iterable[FrameSpec], data_bitrate: int | None = None
             ) -> BusLoad:
    """Load of the frames of ``specs`` (each at its rate) on a bus of ``bitrate``."""
    frames = nominal = worst = 0.0
    for spec in specs:
        bits = spec_bits(spec, bitrate, data_bitrate)
        frames += spec.rate
        nominal += bits[0] * spec.rate
        worst += bits[1] * spec.rate
    return BusLoad(frames, nominal, worst, bitrate)
