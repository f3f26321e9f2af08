"""A simulated Robstride or CyberGear actuator (the protocol: :mod:`hil.protocols.robstride`),
around a DriveCore at the output shaft (the built-in gear folded in, as the frames are).

Private protocol: the run mode (``run_mode``, 0x7005) picks what an enabled motor follows:
operation control (type 1's impedance command), position (``loc_ref``; PP at ``vel_max`` and
``acc_set`` on the RS firmware, CSP at ``limit_spd``, CyberGear's mode 1 as CSP), speed
(``spd_ref`` on a ramp of ``acc_rad`` within ``limit_cur``) or current (``iq_ref``). Every
request is answered as §4.1 says (a feedback frame unless another answer is named). MIT
protocol mode: :class:`MitMode`. A protocol or baud-rate change takes effect at the next
power cycle (``hil sim --fault restart``), as SampleProgram's types 23 and 25 say.

A frame of the other framing (an 11-bit frame to a motor in private mode, a 29-bit one to a
motor in MIT mode) is not for its protocol's receiver: the motor neither acts nor answers
(hil's reading of the manuals: each protocol names its frame format only; LeRobot #3547
reports the silence) and the simulator's log names the bus and the identifier, the first
time per identifier.
"""

from __future__ import annotations

import logging
import struct
from collections.abc import Callable
from contextlib import AbstractContextManager
from dataclasses import replace

from hil.bus_config.types import BusConfig, DriveConfig
from hil.can.frame import Frame
from hil.can.router import Subscription
from hil.drives.core import DriveCore
from hil.drives.definitions import Fault as CoreFault
from hil.drives.definitions import Mode, Power, SilenceReaction
from hil.drives.profile import DriveProfile
from hil.protocols.robstride import Framing, Robstride, RobstrideOptions
from hil.protocols.robstride import params as P
from hil.protocols.robstride.codec import (
    OVERLOAD_WORD_BIT, Fault, Feedback, MotorMode, RunMode, fault_words,
)
from hil.protocols.robstride.drive import private
from hil.protocols.robstride.drive.mit import MitMode
from hil.protocols.robstride.drive.private import BAUD_RATES

log = logging.getLogger(__name__)

#: the motor's temperature (°C): no heating is modelled
AMBIENT = 25.0
#: canTimeout (0x7028) counts 20000 to the second (RS00 manual, parameter table)
TIMEOUT_COUNTS_PER_S = 20000
#: the active report's period at EPScan_time 1, and its step (RS00 manual: "1 = 10 ms, each
#: +1 adds 5 ms")
REPORT_PERIOD, REPORT_STEP = 0.010, 0.005


class RobstrideDrive(DriveProfile):
    """One Robstride or CyberGear actuator on a bus."""

    protocol = Robstride
    options: RobstrideOptions

    def __init__(self, config: DriveConfig, core: DriveCore, lock: AbstractContextManager):
        super().__init__(config, core, lock)
        self.options = config.options or RobstrideOptions()
        self.model = self.options.model
        self.ranges = self.options.ranges()
        self.host = self.options.host_id        # the host the motor last heard from
        #: the protocol it speaks now (None: CANopen or another bit rate, silent here)
        self.framing: Framing | None = self.options.protocol
        self.next_framing: Framing | None = self.framing   # after the next power cycle
        self.baud_code = self.next_baud_code = 1
        self.bitrate = 1_000_000
        self.bus_name = "?"
        self.table = P.table(self.model.cybergear)
        self.saved = {index: p.default for index, p in self.table.items()}
        self.saved[P.LIMIT_TORQUE] = self.ranges.t_max    # "0~12 Nm" (§4.1.12): the range
        self.values = dict(self.saved)
        self.zero = 0.0                          # the mechanical zero (type 6)
        self.faults = Fault(0)
        self.reporting = False                   # active reporting (type 24)
        self._next_report = 0.0
        self._replies: list[Frame] = []
        self._told: set[tuple[bool, int]] = set()
        self.wrong_framing = 0
        self.mit = MitMode(self)
        self._peak = core.parameters.peak_torque
        # canTimeout: "after the timeout the motor enters reset mode" (RS00 manual)
        core.silence_reaction = SilenceReaction.DISABLE
        core.set_mode(Mode.IMPEDANCE)

    # --- bus ----------------------------------------------------------------------------

    def on_bus(self, bus: BusConfig) -> None:
        self.bus_name, self.bitrate = bus.name, bus.bitrate

    def subscriptions(self) -> list[Subscription]:
        """Private: every extended frame naming the motor in bits 7-0; MIT mode: its three
        11-bit command ids. Each also hears the other framing, to say it came."""
        private = [Subscription(self.node_id, self._on_private, extended=True,
                                mask=0xFF)]
        mit = [Subscription(mode << 8 | self.node_id, self.mit.on_frame) for mode in (0, 1, 2)]
        if self.framing is Framing.PRIVATE:
            return [*private, *(replace(s, handler=self._wrong_framing) for s in mit)]
        if self.framing is Framing.MIT:
            return [*mit, *(replace(s, handler=self._wrong_framing) for s in private)]
        return [replace(s, handler=self._wrong_framing) for s in (*private, *mit)]

    def resubscribe(self, change: Callable[[], None]) -> None:
        """Change what the motor listens to (its id, its protocol) while on the bus."""
        router = self.router
        self.detach()
        change()
        if router is not None:
            self.attach(router)

    def _wrong_framing(self, frame: Frame) -> None:
        """A frame of the other framing, or any while silent: ignored, said once per id."""
        self.wrong_framing += 1
        key = (frame.extended, frame.identifier)
        if key in self._told:
            return
        self._told.add(key)
        size = "29-bit" if frame.extended else "11-bit"
        speaks = (f"the {self.framing.value} protocol" if self.framing is not None
                  else "no protocol this bus carries (CANopen or another bit rate)")
        log.warning("bus '%s': %s frame 0x%X reached Robstride motor %d, which speaks %s: "
                    "ignored and unanswered, as the motor's CAN receiver ignores it",
                    self.bus_name, size, frame.identifier, self.node_id, speaks)

    def _on_private(self, frame: Frame) -> None:
        private.on_frame(self, frame)

    def mcu_id(self) -> bytes:
        """hil's 64-bit MCU unique id: "hil" and the config's node id (hil's choice)."""
        return b"hil\0\0\0" + struct.pack("<H", self.config.node_id)

    def take_replies(self) -> list[Frame]:
        replies, self._replies = self._replies, []
        return replies

    def answer_with(self, frame: Frame | None) -> None:
        """The answer of the frame just handled (lock held), sent with the cycle's."""
        self._replies = [frame] if frame is not None else []
        self.on_command(self)

    # --- what both framings do to the motor --------------------------------------------------

    @property
    def enabled(self) -> bool:
        """Running (the feedback's mode 2): what the handlers of both framings ask."""
        return self.core.power is Power.ENABLED

    @property
    def run_mode(self) -> int:
        return int(self.values[P.RUN_MODE])

    def enable(self) -> None:
        """Run in the run mode, holding where it is until a reference comes (an operation
        control motor with zero gains, as an MIT motor enters motor mode)."""
        if self.core.power is Power.FAULT:
            return                # a faulted motor enables only once cleared (type 4, 1)
        if self.core.power is Power.ENABLED and self.core.mode is self.core_mode():
            return                # running so already: nothing changes (hil's reading)
        self.core.set_mode(self.core_mode())
        self.core.enable()
        self.core.hold_position()
        if self.run_mode == RunMode.OPERATION:
            self.core.new_setpoint(position=self.core.status().position, velocity=0.0,
                                   torque=0.0, stiffness=0.0, damping=0.0)
        elif self.run_mode == RunMode.SPEED:
            self.core.new_setpoint(velocity=0.0)
        elif self.run_mode == RunMode.CURRENT:
            self.core.new_setpoint(torque=0.0)
        self._limits()
        if self.run_mode == RunMode.ZERO and not self.model.cybergear:
            self.core.move_to(self.zero)   # "zero mode: back to the mechanical zero"

    def core_mode(self) -> Mode:
        mode = self.run_mode
        if mode == RunMode.OPERATION:
            return Mode.IMPEDANCE
        if mode == RunMode.SPEED:
            return Mode.PROFILE_VELOCITY
        if mode == RunMode.CURRENT:
            return Mode.TORQUE
        return Mode.PROFILE_POSITION

    def set_zero(self) -> None:
        """The mechanical zero here, lost at a power cycle (§4.1.6); not in PP mode (RS00
        manual, MIT §5.6: "PP mode cannot set the zero"). Nothing moves: the targets keep
        their place."""
        if self.run_mode == RunMode.POSITION_PP and not self.model.cybergear:
            return
        self.zero = self.core.status().position

    def clear_faults(self) -> None:
        self.faults = Fault(0)
        if self.core.power is Power.FAULT:
            self.core.reset_fault()

    def set_motor_id(self, new: int) -> None:
        def change() -> None:
            self.node_id = new        # as an LSS master's new id: the simulator finds it there
        self.resubscribe(change)

    def read_value(self, index: int) -> float:
        status = self.core.status()
        measured = {P.MECH_POS: status.position - self.zero, P.MECH_VEL: status.velocity,
                    P.IQF: status.torque / self.model.newton_metres_per_ampere}
        return measured.get(index, self.values[index])

    def write_value(self, index: int, value: float) -> None:
        """A parameter takes effect as §4.2 describes: a run mode change holds where the
        motor is (a reference comes after it), a reference moves an enabled motor of its
        mode, a limit applies at once."""
        self.values[index] = value
        enabled = self.core.power is Power.ENABLED
        if index == P.RUN_MODE and enabled:
            self.enable()
        elif index == P.LOC_REF and enabled and self.core_mode() is Mode.PROFILE_POSITION:
            self.core.move_to(value + self.zero)
        elif index == P.SPD_REF and enabled and self.run_mode == RunMode.SPEED:
            self.core.new_setpoint(velocity=value)
        elif index == P.IQ_REF and enabled and self.run_mode == RunMode.CURRENT:
            amperes = max(-self.model.current_max, min(self.model.current_max, value))
            self.core.new_setpoint(torque=amperes * self.model.newton_metres_per_ampere)
        elif index == P.CAN_TIMEOUT:
            self.core.parameters = replace(self.core.parameters,
                                           watchdog_timeout=value / TIMEOUT_COUNTS_PER_S)
        self._limits()

    def _limits(self) -> None:
        """The mode's profile and torque cap: limit_torque everywhere, limit_cur in speed
        and position modes; PP moves at vel_max/acc_set, CSP (and CyberGear's position
        mode) at limit_spd with the speed loop's own ramp, speed mode on acc_rad."""
        values, kt = self.values, self.model.newton_metres_per_ampere
        peak = min(self._peak, max(0.0, values[P.LIMIT_TORQUE]))
        if self.run_mode in (RunMode.SPEED, RunMode.POSITION_PP, RunMode.POSITION_CSP):
            peak = min(peak, values[P.LIMIT_CUR] * kt)
        speed, acceleration = values[P.LIMIT_SPD], 1e9
        if self.run_mode == RunMode.POSITION_PP and not self.model.cybergear:
            speed, acceleration = values[P.VEL_MAX], values[P.ACC_SET]
        elif self.run_mode == RunMode.SPEED:
            speed, acceleration = self.ranges.v_max, values.get(P.ACC_RAD, 1e9)
        self.core.parameters = replace(
            self.core.parameters, peak_torque=peak, profile_velocity=speed or 1e-6,
            profile_acceleration=acceleration or 1e9, profile_deceleration=acceleration or 1e9)

    # --- what the motor reports ----------------------------------------------------------

    def reported(self) -> Feedback:
        status = self.core.status()
        mode = MotorMode.RUN if self.core.power is Power.ENABLED else MotorMode.RESET
        return Feedback(self.node_id, status.position - self.zero, status.velocity,
                        status.torque, AMBIENT, mode, self.faults)

    def fault_word(self) -> int:
        """Type 21's word: a drive fault hil injects is the stall overload (bit 14)."""
        return OVERLOAD_WORD_BIT if self.faults else 0

    def after_update(self) -> None:
        """A drive fault hil injects: reported as a stall overload (RS: feedback bit 20,
        SampleProgram ``mapFaults``) or, on a CyberGear, an overcurrent (bit 17), the motor
        released until a stop with byte 0 = 1 clears it (hil's choice of the nearest
        faults). A silence past canTimeout: reset mode, no fault bit."""
        for fault in self.take_events():
            if fault is not CoreFault.CONTROLLER_SILENT:
                self.faults |= Fault.OVERCURRENT if self.model.cybergear else Fault.STALL_OVERLOAD

    def tick(self, now: float) -> None:
        """Active reporting: a type 2 frame every EPScan_time period (private protocol)."""
        if not (self.reporting and self.attached and self.framing is Framing.PRIVATE):
            return
        if now >= self._next_report:
            period = REPORT_PERIOD + REPORT_STEP * (self.values.get(P.EPSCAN_TIME, 1) - 1)
            late = now - self._next_report >= period      # (re)started: from now on
            self._next_report = (now if late else self._next_report) + period
            self.send(private.feedback_frame(self))

    def restart(self) -> None:
        """A power cycle: the zero and unsaved parameters lost (§4.1.6, §4.1.9), reporting
        off, and the protocol and baud rate of types 23/25 in force."""
        super().restart()

        def boot() -> None:
            self.framing = self.next_framing
            self.baud_code = self.next_baud_code
            if BAUD_RATES[self.baud_code] != self.bitrate:
                self.framing = None           # another bit rate: it hears nothing here
        self.resubscribe(boot)
        self.values = dict(self.saved)
        self.zero, self.faults, self.reporting = 0.0, Fault(0), False
        self.core.set_mode(self.core_mode())

    @property
    def state_text(self) -> str:
        if self.faults:
            return "FAULT " + fault_words(self.faults, self.model.cybergear)
        if self.framing is None:
            return "SILENT (another protocol or bit rate)"
        return MotorMode.RUN.name if self.core.power is Power.ENABLED else MotorMode.RESET.name
