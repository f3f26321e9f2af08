"""The registers a Damiao DM-J motor serves on CAN id 0x7FF (read 0x33, write 0x55, save
0xAA), by number, with their types and access as the maker's register table has them
(Damiao's DM-J manuals; the sample code's ``is_in_ranges``: registers 7-10, 13-16 and 35-36
are uint32, the others float32).

What a register means to hil's simulated motor is said in :mod:`hil.protocols.damiao.drive`;
the rest are kept and read back as written.
"""

from __future__ import annotations

import enum
import struct
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
