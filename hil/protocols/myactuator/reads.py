"""What an RMD motor reports (protocol V4.2 §2.6-2.16, §2.24, §2.28): the reads of
:class:`hil.protocols.myactuator.drive.MyActuatorDrive`, from its core's state at the output
shaft. None moves the motor.
"""

from __future__ import annotations

import math
import struct

from hil.protocols.myactuator.codec import (
    ENCODER_LINES, Command, MotorState, pack_phase_currents, pack_state, pack_status_1,
    with_value,
)

#: the temperature every reply carries (°C): no heating is modelled
AMBIENT = 25
DEGREE = math.pi / 180


class MotorReads:
    """The read commands' answers, for a drive with ``core``, ``model``, ``options``,
    ``zero`` (rad), ``error``, ``brake_released``, ``run_mode``, ``clock`` and
    ``booted_at``."""

    def pulses(self, position: float) -> int:
        """Encoder pulses of an output position: 16384 lines a rotor turn (the codec)."""
        return round(position / (2 * math.pi) * ENCODER_LINES * self.model.gear_ratio)

    def position(self, pulses: int) -> float:
        return pulses / (ENCODER_LINES * self.model.gear_ratio) * 2 * math.pi

    def state(self) -> MotorState:
        status = self.core.status()
        return MotorState(AMBIENT, status.torque / self.model.torque_constant,
                          status.velocity / DEGREE, (status.position - self.zero) / DEGREE)

    def _state_reply(self, data: bytes) -> bytes:
        return pack_state(data[0], self.state())

    def _encoder(self, data: bytes) -> bytes:
        """0x60 from the zero, 0x61 raw, 0x62 the zero offset (§2.6-2.8), in pulses."""
        raw, offset = self.pulses(self.core.status().position), self.pulses(self.zero)
        value = {Command.READ_MULTI_TURN_ENCODER: raw - offset,
                 Command.READ_MULTI_TURN_ORIGINAL: raw, Command.READ_MULTI_TURN_ZERO_OFFSET:
                 offset}[data[0]]
        return with_value(data[:4], value)

    def _single_turn_encoder(self, data: bytes) -> bytes:
        """§2.11: the rotor's turn: position from the zero, raw, zero offset (uint16)."""
        raw = self.pulses(self.core.status().position) % ENCODER_LINES
        offset = self.pulses(self.zero) % ENCODER_LINES
        return struct.pack("<BxHHH", data[0], (raw - offset) % ENCODER_LINES, raw, offset)

    def _angle(self, data: bytes) -> bytes:
        """0x92: multi-turn, int32 0.01° (§2.12); 0x94: the turn, uint16 0-35999 (§2.13)."""
        degrees = (self.core.status().position - self.zero) / DEGREE
        if data[0] == Command.READ_MULTI_TURN_ANGLE:
            return with_value(data[:4], round(degrees * 100))
        return data[:6] + struct.pack("<H", round(degrees * 100) % 36000)

    def _status_1(self, data: bytes) -> bytes:
        return pack_status_1(AMBIENT, self.brake_released, self.options.supply_voltage,
                             self.error)

    def _status_3(self, data: bytes) -> bytes:
        status = self.core.status()
        return pack_phase_currents(AMBIENT, status.torque / self.model.torque_constant,
                                   status.position * self.model.gear_ratio
                                   * self.model.pole_pairs)

    def _operating_mode(self, data: bytes) -> bytes:
        return data[:7] + bytes([self.run_mode])

    def _power(self, data: bytes) -> bytes:
        """0x71 (2b-t/myactuator_rmd: uint16 0.1 W in bytes 6-7; not in V4.2): the shaft's
        mechanical power (hil models no losses)."""
        status = self.core.status()
        watts = abs(status.torque * status.velocity)
        return data[:6] + struct.pack("<H", min(round(watts * 10), 0xFFFF))

    def _runtime(self, data: bytes) -> bytes:
        """§2.28: ms since the last start, uint32."""
        return with_value(data[:4], round((self.clock() - self.booted_at) * 1000) & 0xFFFFFFFF,
                          signed=False)
