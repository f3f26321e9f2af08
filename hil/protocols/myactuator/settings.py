"""An RMD motor's settings commands (protocol V4.2 §2.1-2.5, §2.9-2.10, §2.29-2.34, §4):
what each stores, what each answers. None of them moves the motor; what goes to ROM and
takes effect "after restarting" is kept for the next start (:meth:`Settings.restart`).

The document gives no factory values: hil starts the PID parameters at 1.0 (§2.1.5's
example reads 1.0), the four accelerations at 10000 dps/s (§2.4.5's examples), the CANID
filter off (so the multi-motor and CANID commands are heard, §2.34.4), no angle limits.
The PID parameters are stored and answered, not acted on: hil's loops are its drive core's.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field

from hil.protocols.myactuator import VERSION_DATE
from hil.protocols.myactuator.codec import (
    MOTOR_IDS, REPLY_BASE, Command, value_of, with_value,
)

#: the PID parameters' indexes (§2.1.4): current, speed, position loop KP/KI(/KD)
PID_INDEXES = (0x01, 0x02, 0x04, 0x05, 0x07, 0x08, 0x09)
#: an acceleration's range (§2.4.3: "100-60000" dps/s); 0 plans nothing (§2.21.1)
ACCELERATION_RANGE = range(100, 60001)


def _default_pid() -> dict[int, float]:
    return dict.fromkeys(PID_INDEXES, 1.0)


@dataclass
class Settings:
    """What the settings commands set."""

    #: the CAN id from the next start on (0x79 write, §4; 0x20 index 5)
    next_id: int
    pid: dict[int, float] = field(default_factory=_default_pid)
    pid_rom: dict[int, float] = field(default_factory=_default_pid)
    #: position planning acceleration, deceleration; speed planning's (dps/s; §2.4.4)
    acceleration: list[int] = field(default_factory=lambda: [10000] * 4)
    #: the zero offset the next start takes (rad at the output; §2.9, §2.10, 0x20 index 1)
    rom_zero: float = 0.0
    #: the communication interruption protection time (ms, §2.30; 0: off)
    timeout_ms: int = 0
    baud_code: int = 1                   # §2.31: CAN 0 500 kbit/s, 1 1 Mbit/s
    can_filter: bool = False             # §2.34.4 index 2
    error_report: bool = False           # index 3: stored; hil sends no periodic 0x9A
    multi_turn_save: bool = True         # index 4: stored
    #: the position modes' limits (degrees; 0x20 indexes 6 and 7, in 0.01° as every
    #: angle the document gives: hil's reading, the section names no unit)
    angle_limits: tuple[float, float] = (-math.inf, math.inf)
    #: active replies asked for (0xB6): command -> interval (10 ms units); stored, not sent
    active: dict[int, int] = field(default_factory=dict)

    def restart(self) -> None:
        """A start: the PID parameters from ROM."""
        self.pid = dict(self.pid_rom)

    def command(self, drive, data: bytes) -> bytes | None:
        """The answer to a settings command of ``drive`` (its position and model at hand)."""
        return SETTINGS[data[0]](self, drive, data)

    def _read_pid(self, drive, data: bytes) -> bytes:
        """§2.1: the float of the index in bytes 4-7 (0 for an index the table lacks)."""
        return data[:2] + bytes(2) + struct.pack("<f", self.pid.get(data[1], 0.0))

    def _write_pid(self, drive, data: bytes) -> bytes:
        """§2.2 (RAM), §2.3 (RAM and ROM): answered with the command."""
        if data[1] in PID_INDEXES:
            value = struct.unpack_from("<f", data, 4)[0]
            self.pid[data[1]] = value
            if data[0] == Command.WRITE_PID_ROM:
                self.pid_rom[data[1]] = value
        return data

    def _read_acceleration(self, drive, data: bytes) -> bytes:
        index = data[1]
        return with_value(data[:2] + bytes(2), self.acceleration[index] if index < 4 else 0)

    def _write_acceleration(self, drive, data: bytes) -> bytes:
        """§2.5: answered with the command; a value outside 100-60000 (and not 0) is not
        taken (hil's choice: the document gives the range only)."""
        value = value_of(data, signed=False)
        if data[1] < 4 and (value == 0 or value in ACCELERATION_RANGE):
            self.acceleration[data[1]] = value
        return data

    def _write_encoder_zero(self, drive, data: bytes) -> bytes:
        """§2.9: the zero offset given in pulses, for the next start."""
        self.rom_zero = drive.position(value_of(data))
        return data

    def _write_current_zero(self, drive, data: bytes) -> bytes:
        """§2.10: here as the zero, effective after a restart (0x76); answered with it."""
        self.rom_zero = drive.core.status().position
        return with_value(data[:4], drive.pulses(self.rom_zero))

    def _canid(self, drive, data: bytes) -> bytes:
        """§4: DATA[2] 0 writes DATA[7] (1-32), answered with the command; 1 reads,
        answered with the reply id in bytes 6-7."""
        if data[2] == 0:
            if data[7] in MOTOR_IDS:
                self.next_id = data[7]
            return data
        return data[:6] + struct.pack("<H", REPLY_BASE + drive.node_id)

    def _version_date(self, drive, data: bytes) -> bytes:
        return with_value(data[:4], VERSION_DATE, signed=False)

    def _can_timeout(self, drive, data: bytes) -> bytes:
        """§2.30: ms, uint32, answered with the command."""
        self.timeout_ms = value_of(data, signed=False)
        return data

    def _baud_rate(self, drive, data: bytes) -> bytes:
        """§2.31: taken at the next start. "The reply command is random and need not be
        processed": hil answers with the command."""
        if data[7] in (0, 1):
            self.baud_code = data[7]
        return data

    def _model(self, drive, data: bytes) -> bytes:
        """§2.32: seven ASCII characters (``X8-20``, padded with spaces)."""
        return data[:1] + drive.model.name.encode("ascii")[:7].ljust(7)

    def _active_reply(self, drive, data: bytes) -> bytes | None:
        """§2.33: enabling is not answered ("the data will not be returned"); hil stores
        the request and sends no active replies (not modelled)."""
        if data[2] == 1:
            self.active[data[1]] = data[3] | data[4] << 8
            return None
        self.active.pop(data[1], None)
        return data

    def _function_control(self, drive, data: bytes) -> bytes:
        """§2.34, answered with the command."""
        index, value = data[1], value_of(data)
        if index == 1:                   # clear multi-turn value: here, after restarting
            self.rom_zero = drive.core.status().position
        elif index == 2:
            self.can_filter = value == 1
        elif index == 3:
            self.error_report = value == 1
        elif index == 4:
            self.multi_turn_save = value == 1
        elif index == 5 and value in MOTOR_IDS:
            self.next_id = value
        elif index == 6:
            self.angle_limits = (self.angle_limits[0], abs(value) / 100)
        elif index == 7:
            self.angle_limits = (-abs(value) / 100, self.angle_limits[1])
        return data


#: each settings command's handler
SETTINGS = {
    Command.READ_PID: Settings._read_pid, Command.WRITE_PID_RAM: Settings._write_pid,
    Command.WRITE_PID_ROM: Settings._write_pid,
    Command.READ_ACCELERATION: Settings._read_acceleration,
    Command.WRITE_ACCELERATION: Settings._write_acceleration,
    Command.WRITE_ENCODER_ZERO: Settings._write_encoder_zero,
    Command.WRITE_CURRENT_ZERO: Settings._write_current_zero, Command.CANID: Settings._canid,
    Command.READ_VERSION_DATE: Settings._version_date,
    Command.CAN_TIMEOUT: Settings._can_timeout, Command.BAUD_RATE: Settings._baud_rate,
    Command.READ_MODEL: Settings._model, Command.ACTIVE_REPLY: Settings._active_reply,
    Command.FUNCTION_CONTROL: Settings._function_control,
}
