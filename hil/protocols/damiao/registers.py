"""The registers a Damiao DM-J motor serves on CAN id 0x7FF (read 0x33, write 0x55, save
0xAA), by number, with their types and access as the maker's register table has them
(Damiao's DM-J manuals; the sample code's ``is_in_ranges``: registers 7-10, 13-16 and 35-36
are uint32, the others float32).

What a register means to hil's simulated motor is said in :mod:`hil.protocols.damiao.drive`;
the rest are kept and read back as written.
"""

from __future__ import annotations

import enum
import math
import struct
from collections.abc import Mapping
from dataclasses import dataclass

from hil.protocols.damiao.models import DamiaoModel


class Op(enum.IntEnum):
    """Byte 2 of a frame on 0x7FF (and of the motor's answer)."""

    READ = 0x33
    WRITE = 0x55
    SAVE = 0xAA
    REFRESH = 0xCC       # answered with a feedback frame


#: the id every register request is sent to
REGISTER_ID = 0x7FF


@dataclass(frozen=True)
class Register:
    number: int
    name: str
    integer: bool        # uint32 (else float32)
    writable: bool

    def encode(self, value: float) -> bytes:
        return (struct.pack("<I", int(value) & 0xFFFFFFFF) if self.integer
                else struct.pack("<f", float(value)))

    def decode(self, data: bytes) -> float:
        return struct.unpack("<I" if self.integer else "<f", data)[0]


def _table(*rows: tuple[int, str, bool, bool]) -> dict[int, Register]:
    return {number: Register(number, name, integer, writable)
            for number, name, integer, writable in rows}


RW, RO, U32, F32 = True, False, True, False
REGISTERS = _table(
    (0, "UV_Value", F32, RW), (1, "KT_Value", F32, RW), (2, "OT_Value", F32, RW),
    (3, "OC_Value", F32, RW), (4, "ACC", F32, RW), (5, "DEC", F32, RW), (6, "MAX_SPD", F32, RW),
    (7, "MST_ID", U32, RW), (8, "ESC_ID", U32, RW), (9, "TIMEOUT", U32, RW),
    (10, "CTRL_MODE", U32, RW), (11, "Damp", F32, RO), (12, "Inertia", F32, RO),
    (13, "hw_ver", U32, RO), (14, "sw_ver", U32, RO), (15, "SN", U32, RO), (16, "NPP", U32, RO),
    (17, "Rs", F32, RO), (18, "Ls", F32, RO), (19, "Flux", F32, RO), (20, "Gr", F32, RO),
    (21, "PMAX", F32, RW), (22, "VMAX", F32, RW), (23, "TMAX", F32, RW), (24, "I_BW", F32, RW),
    (25, "KP_ASR", F32, RW), (26, "KI_ASR", F32, RW), (27, "KP_APR", F32, RW),
    (28, "KI_APR", F32, RW), (29, "OV_Value", F32, RW), (30, "GREF", F32, RW),
    (31, "Deta", F32, RW), (32, "V_BW", F32, RW), (33, "IQ_c1", F32, RW), (34, "VL_c1", F32, RW),
    (35, "can_br", U32, RW), (36, "sub_ver", U32, RO),
    (50, "u_off", F32, RO), (51, "v_off", F32, RO), (52, "k1", F32, RO), (53, "k2", F32, RO),
    (54, "m_off", F32, RO), (55, "dir", F32, RO), (59, "Imax", F32, RO), (60, "VBus", F32, RO),
    (61, "Tpcb", F32, RO), (62, "Tmtr", F32, RO), (63, "Iu_off", F32, RO),
    (64, "Iv_off", F32, RO), (65, "Iw_off", F32, RO), (80, "p_m", F32, RO),
    (81, "xout", F32, RO),
)
BY_NAME = {register.name: register.number for register in REGISTERS.values()}

@dataclass(frozen=True)
class Bounds:
    """The values a register write is taken with: ``low < value < high``, each end
    included where its flag says so."""

    low: float = -math.inf
    high: float = math.inf
    with_low: bool = True
    with_high: bool = True

    def admit(self, value: float) -> bool:
        above = value >= self.low if self.with_low else value > self.low
        below = value <= self.high if self.with_high else value < self.high
        return above and below


_POSITIVE, _NOT_NEGATIVE = Bounds(0.0, with_low=False), Bounds(0.0)
_BANDWIDTH = Bounds(100.0, 10000.0)
#: what a DM4310 takes in a write, by register, as its firmware checks each one (recovered
#: in github.com/umeow0716/damiao_firmware, app/src/parameter_protocol.c, write_register;
#: its bit-pattern comparisons read here as the floats they bound). OV_Value must also be
#: above UV_Value (:func:`accepts`). A register not here takes no write.
WRITABLE = {
    0: Bounds(10.0, with_low=False),        # UV_Value, V
    1: _NOT_NEGATIVE,                       # KT_Value
    2: Bounds(80.0, 200.0, with_high=False),  # OT_Value, °C
    3: Bounds(0.0, 1.0, False, False),      # OC_Value, a share of the driver's current
    4: _POSITIVE,                           # ACC
    5: Bounds(high=0.0, with_high=False),   # DEC (negative)
    6: _POSITIVE,                           # MAX_SPD
    7: Bounds(0, 0xFFFFFFFF), 8: Bounds(0, 0xFFFFFFFF),   # MST_ID, ESC_ID: kept & 0x7FF
    9: Bounds(0, 0xFFFFFFFF),               # TIMEOUT
    10: Bounds(1, 4),                       # CTRL_MODE: MIT .. force-position
    21: _POSITIVE, 22: _POSITIVE, 23: _POSITIVE,          # PMAX, VMAX, TMAX
    24: _BANDWIDTH,                         # I_BW
    25: _NOT_NEGATIVE, 26: _NOT_NEGATIVE,   # KP_ASR, KI_ASR
    27: _NOT_NEGATIVE, 28: _NOT_NEGATIVE,   # KP_APR, KI_APR
    29: Bounds(high=32.0),                  # OV_Value, V (and above UV_Value)
    30: Bounds(0.0, 1.0, with_low=False),   # GREF
    31: Bounds(1.0, 30.0),                  # Deta
    32: _POSITIVE,                          # V_BW
    33: _BANDWIDTH,                         # IQ_c1
    34: Bounds(0.0, 10000.0, with_low=False),  # VL_c1
    35: Bounds(0, 11),                      # can_br: a rate code
}
#: the id registers keep their value's low 11 bits, as the firmware stores them
ID_REGISTERS = (7, 8)


def accepts(number: int, value: float, registers: Mapping[int, float]) -> bool:
    """Whether register ``number`` takes ``value`` in a write. Never a value that is not a
    finite number: where the firmware's own check lets infinity or NaN through (PMAX's
    ``value > 0``, V_BW's sign test), its mapping and loops would then compute with it
    (hil's choice: refused, the register kept)."""
    bounds = WRITABLE.get(number)
    if bounds is None or not math.isfinite(value) or not bounds.admit(value):
        return False
    return number != 29 or value > registers[0]          # OV_Value above UV_Value


#: TIMEOUT's unit (s): "1 register unit = 50 microseconds" (the maker's register table)
TIMEOUT_UNIT = 50e-6
#: the temperature a motor reports (°C): hil models no heating
AMBIENT = 25.0


def initial_values(model: DamiaoModel, node_id: int, master_id: int, control_mode: int,
                   watchdog_timeout: float) -> dict[int, float]:
    """Every register's value as a motor of ``model`` configured so comes up with: the
    model's own figures where the maker publishes them; the rest 0 (hil's choice: the maker
    publishes no factory defaults for them; a motor's own are calibration results)."""
    values = dict.fromkeys(REGISTERS, 0.0)
    values.update({
        1: model.torque_constant, 6: model.v_max, 7: master_id, 8: node_id,
        9: round(watchdog_timeout / TIMEOUT_UNIT), 10: control_mode,
        12: model.rotor_inertia, 16: model.pole_pairs, 17: model.phase_resistance,
        18: model.phase_inductance, 19: model.flux_linkage, 20: model.gear_ratio,
        21: model.p_max, 22: model.v_max, 23: model.t_max,
        35: 4,                                        # can_br: code 4 is 1 Mbit/s
        59: model.driver_max_current, 60: model.supply_voltage, 61: AMBIENT, 62: AMBIENT,
    })
    return values
