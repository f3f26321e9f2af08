"""The master's side of a moteus controller (the protocol: :mod:`hil.protocols.moteus`):
each cycle one frame from the master's id with the reply bit, a position command (mode 10,
position, velocity, feed-forward torque) and a query (mode, position, velocity, torque,
fault), as the moteus library's ``make_position(..., query=True)`` sends it; until the
controller is heard, the query alone. The reply's mode tells the state: 1 is a fault
(its code in 0x00f), 11 the controller's watchdog fired; a reset sends a stop (mode 0),
the only way out of either (registers.md "0x000 - Mode"; fw ``ISR_MaybeChangeMode``).
"""

from __future__ import annotations

import math

from hil.can.frame import Frame
from hil.can.router import Subscription
from hil.hardware.axis import Axis, AxisCommand, AxisFault, FaultKind
from hil.protocols.moteus import (
    QUERY, STOP, TURN, Moteus, MoteusOptions, identifier, moteus_frame, position_command,
)
from hil.protocols.moteus import multiplex
from hil.protocols.moteus.registers import FAULTS, Mode, Register, from_raw, scale_of


class MoteusAxis(Axis):
    protocol = Moteus

    def __init__(self, config, bus_name, on_feedback=lambda: None):
        super().__init__(config, bus_name, on_feedback)
        options: MoteusOptions = config.options or MoteusOptions()
        self._to = identifier(options.master_id, self.node_id, True, options.can_prefix)
        self._from = identifier(self.node_id, options.master_id, False, options.can_prefix)
        self.mode = Mode.STOPPED
        self.fault_code = 0
        self._hold: float | None = None
        self._stop_next = False

    def subscriptions(self) -> list[Subscription]:
        return [Subscription(self._from, self._on_reply, extended=self._from > 0x7FF)]

    def _on_reply(self, frame: Frame) -> None:
        values: dict[int, float] = {}
        for part in multiplex.parse(frame.data):
            if isinstance(part, multiplex.Values) and part.base == multiplex.REPLY:
                values.update({register: from_raw(raw, scale_of(register), part.kind)
                               for register, raw in part.values.items()
                               if register in (Register.MODE, Register.POSITION,
                                               Register.VELOCITY, Register.TORQUE,
                                               Register.FAULT)})
        if Register.POSITION not in values or Register.MODE not in values:
            return                        # not the answer to our query
        self.mode = Mode(int(values[Register.MODE]))
        self.fault_code = int(values.get(Register.FAULT, 0))
        self.feedback.position = values[Register.POSITION] * TURN
        self.feedback.velocity = values.get(Register.VELOCITY, 0.0) * TURN
        self.feedback.torque = values.get(Register.TORQUE, 0.0)
        self.booted.set()
        self.answered()

    @property
    def state(self) -> str:
        return self.mode.name.replace("_", " ")

    @property
    def enabled(self) -> bool:
        return self.mode == Mode.POSITION

    def _frame(self, payload: bytes) -> Frame:
        return moteus_frame(self._to, payload + QUERY)

    def cycle_frames(self, command: AxisCommand) -> list[Frame]:
        if not self.booted.is_set():
            return [self._frame(b"")]
        if self._stop_next:
            self._stop_next = False
            return [self._frame(STOP)]
        if command.stopping or command.holding:
            if self._hold is None:
                self._hold = self.feedback.position
            torque = 0.0 if command.stopping else command.torque
            return [self._frame(position_command(self._hold / TURN, 0.0, torque))]
        self._hold = None
        velocity = command.velocity if math.isfinite(command.velocity) else 0.0
        return [self._frame(position_command(command.target / TURN, velocity / TURN,
                                             command.torque))]

    def disable_rounds(self) -> list[list[Frame]]:
        return [[self._frame(STOP)]]

    def fault(self, stopping: bool = False) -> AxisFault | None:
        if self.mode == Mode.FAULT:
            words = FAULTS.get(self.fault_code, "fault")
            return self.found(FaultKind.FAULT, f"reports fault {self.fault_code} ({words})",
                              self.fault_code)
        if self.mode == Mode.POSITION_TIMEOUT:
            return self.found(FaultKind.FAULT, "timed out (mode 11: its watchdog expired)",
                              int(Mode.POSITION_TIMEOUT))
        return None

    def forget_faults(self) -> None:
        self._hold = None
        self._stop_next = True           # a stop: the only way out of fault and timeout
