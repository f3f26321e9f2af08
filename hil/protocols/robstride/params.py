"""The single parameters a master reads (type 17) and writes (type 18): CyberGear manual
§4.1.12's table (0x7005-0x7020), with the RS firmware's additions the maker's code names
(SampleProgram ``RobStride01.cpp``: acc_rad 0x7022, vel_max 0x7024, acc_set 0x7025;
``robstride-dynamics`` 0.0.1 ``protocol.py``: spd_filt_gain 0x7021, EPScan_time 0x7026,
canTimeout 0x7028, zero_sta 0x7029). Values travel little-endian in bytes 4-7, a uint8 in
byte 4 (§4.1.8).
"""

from __future__ import annotations

import struct
from dataclasses import dataclass


@dataclass(frozen=True)
class Parameter:
    """One entry of the table."""

    index: int
    name: str
    kind: str                  # struct code, little-endian: "B", "h", "H", "I", "f"
    writable: bool = True
    default: float = 0.0
    #: only on the RS firmware (not in CyberGear's §4.1.12)
    rs_only: bool = False

    def pack(self, value: float) -> bytes:
        """Bytes 4-7 of a frame carrying ``value``."""
        raw = round(value) if self.kind != "f" else value
        return struct.pack("<" + self.kind, raw).ljust(4, b"\0")

    def unpack(self, data: bytes) -> float:
        return struct.unpack_from("<" + self.kind, bytes(data), 4)[0]


RUN_MODE, IQ_REF, SPD_REF, LIMIT_TORQUE = 0x7005, 0x7006, 0x700A, 0x700B
LOC_REF, LIMIT_SPD, LIMIT_CUR = 0x7016, 0x7017, 0x7018
MECH_POS, IQF, MECH_VEL, VBUS = 0x7019, 0x701A, 0x701B, 0x701C
ACC_RAD, VEL_MAX, ACC_SET, EPSCAN_TIME, CAN_TIMEOUT = 0x7022, 0x7024, 0x7025, 0x7026, 0x7028

#: every parameter by index; defaults the manual's (limit_spd 2 rad/s, limit_cur 23 A
#: §3.3.3 and §4.1.12; acc_rad 20, vel_max and acc_set 10: the RS00 manual's table)
TABLE = {parameter.index: parameter for parameter in (
    Parameter(RUN_MODE, "run_mode", "B"),
    Parameter(IQ_REF, "iq_ref", "f"),
    Parameter(SPD_REF, "spd_ref", "f"),
    Parameter(LIMIT_TORQUE, "limit_torque", "f"),        # the drive starts it at its t_max
    Parameter(0x7010, "cur_kp", "f", default=0.125),
    Parameter(0x7011, "cur_ki", "f", default=0.0158),
    Parameter(0x7014, "cur_filt_gain", "f", default=0.1),
    Parameter(LOC_REF, "loc_ref", "f"),
    Parameter(LIMIT_SPD, "limit_spd", "f", default=2.0),
    Parameter(LIMIT_CUR, "limit_cur", "f", default=23.0),
    Parameter(MECH_POS, "mechPos", "f", writable=False),
    Parameter(IQF, "iqf", "f", writable=False),
    Parameter(MECH_VEL, "mechVel", "f", writable=False),
    Parameter(VBUS, "VBUS", "f", writable=False, default=48.0),
    Parameter(0x701D, "rotation", "h"),
    Parameter(0x701E, "loc_kp", "f", default=30.0),
    Parameter(0x701F, "spd_kp", "f", default=1.0),
    Parameter(0x7020, "spd_ki", "f", default=0.002),
    Parameter(0x7021, "spd_filt_gain", "f", default=0.1, rs_only=True),
    Parameter(ACC_RAD, "acc_rad", "f", default=20.0, rs_only=True),
    Parameter(VEL_MAX, "vel_max", "f", default=10.0, rs_only=True),
    Parameter(ACC_SET, "acc_set", "f", default=10.0, rs_only=True),
    Parameter(EPSCAN_TIME, "EPScan_time", "H", default=1.0, rs_only=True),
    Parameter(CAN_TIMEOUT, "canTimeout", "I", rs_only=True),
    Parameter(0x7029, "zero_sta", "B", rs_only=True),
)}


def table(cybergear: bool) -> dict[int, Parameter]:
    """The parameters a model's firmware has."""
    return {index: p for index, p in TABLE.items() if not (cybergear and p.rs_only)}


def parameter_frame(index: int, value: bytes = bytes(4)) -> bytes:
    """The 8 data bytes of a type 17/18 frame: index little-endian, two zero bytes, value."""
    return struct.pack("<HH", index, 0) + value


def index_of(data: bytes) -> int:
    return struct.unpack_from("<H", bytes(data))[0]
