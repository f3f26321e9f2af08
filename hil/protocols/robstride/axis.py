"""The master's side of a Robstride or CyberGear actuator (the protocol:
:mod:`hil.protocols.robstride`): the private protocol in operation control mode, the run
mode the motor boots in (CyberGear §4.2.2: "after power-on it is in operation control mode
by default"): enable (type 3) at standstill, then one motion-control command (type 1) a
cycle with the drive's gains, each answered with feedback (type 2), whose mode and fault
bits the axis reads. A fault the motor reports is cleared on a reset by a stop with byte 0
= 1 (§4.1.5).
"""

from __future__ import annotations

from hil.bus_config.types import DriveConfig
from hil.can.frame import Frame
from hil.can.router import Subscription
from hil.hardware.axis import Axis, AxisCommand, AxisFault, FaultKind
from hil.protocols.mit.axis import MitAxis
from hil.protocols.robstride import Framing, Robstride, RobstrideOptions
from hil.protocols.robstride.codec import (
    MODE_NAMES, TYPE_AND_IDS, Comm, Fault, Motion, MotorMode, fault_words, pack_motion,
    private_id, unpack_feedback,
)

#: a stop's data: byte 0 = 1 clears the faults (§4.1.5)
STOP, CLEAR_FAULTS = bytes(8), bytes([1]) + bytes(7)


class RobstrideAxis(Axis):
    protocol = Robstride

    def __init__(self, config: DriveConfig, bus_name: str, on_feedback=lambda: None):
        super().__init__(config, bus_name, on_feedback)
        options: RobstrideOptions = config.options or RobstrideOptions()
        MitAxis.require(config, options.protocol is Framing.PRIVATE and options.kp > 0,
                        "Robstride motors in the private protocol", "protocol: private")
        self.kp, self.kd, self.host = options.kp, options.kd, options.host_id
        self.ranges, self.cybergear = options.ranges(), options.model.cybergear
        self.running = False               # enable sent and not stopped since
        self.reported = MotorMode.RESET
        self.faults = Fault(0)
        self._special: tuple[Comm, bytes] | None = None   # sent in place of a command
        self._hold: float | None = None

    def subscriptions(self) -> list[Subscription]:
        """The motor's feedback to this host, whatever its mode and fault bits."""
        return [Subscription(private_id(Comm.FEEDBACK, self.node_id, self.host),
                             self._heard_feedback, extended=True, mask=TYPE_AND_IDS)]

    def _heard_feedback(self, frame: Frame) -> None:
        if len(frame.data) != 8:
            return
        try:
            answer = unpack_feedback(frame.identifier, frame.data, self.ranges)
        except ValueError:
            return                       # a mode the manual does not define
        self.reported, self.faults = answer.mode, answer.faults
        feedback = self.feedback
        feedback.position, feedback.velocity = answer.position, answer.velocity
        feedback.torque = answer.torque
        self.booted.set()
        self.answered()

    def _frame(self, comm: Comm, data: bytes = STOP) -> Frame:
        return Frame(private_id(comm, self.host, self.node_id), data, True)

    def _command(self, motion: Motion) -> Frame:
        identifier, data = pack_motion(motion, self.ranges, self.node_id)
        return Frame(identifier, data, True)

    def cycle_frames(self, command: AxisCommand) -> list[Frame]:
        if self._special is not None:
            comm, data = self._special
            self._special = None
            return [self._frame(comm, data)]
        if not self.running and not command.stopping and self.at_standstill():
            self.running = True
            self._hold = self.feedback.position
            return [self._frame(Comm.ENABLE)]
        if not self.running:       # answered with feedback, followed by no motor at rest
            return [self._command(Motion(self.feedback.position, 0.0, 0.0, 0.0, 0.0))]
        if command.stopping or command.holding:
            if self._hold is None:
                self._hold = self.feedback.position
            torque = 0.0 if command.stopping else command.torque
            return [self._command(Motion(self._hold, 0.0, self.kp, self.kd, torque))]
        self._hold = None
        return [self._command(Motion(command.target, command.velocity, self.kp, self.kd,
                                     command.torque))]

    def reset(self) -> None:
        """Stopped first (the next cycle's frame), enabled again at standstill."""
        super().reset()
        self._special = (Comm.STOP, STOP)
        self.running = False

    def fault(self, stopping: bool = False) -> AxisFault | None:
        if self.faults:
            words = fault_words(self.faults, self.cybergear)
            return self.found(FaultKind.FAULT, f"reports {words}", int(self.faults))
        return None

    def forget_faults(self) -> None:
        self._hold = None
        self.faults = Fault(0)
        self.running = False
        self._special = (Comm.STOP, CLEAR_FAULTS)

    @property
    def state(self) -> str:
        return MODE_NAMES[self.reported]

    @property
    def enabled(self) -> bool:
        return self.running

    def disable_rounds(self) -> list[list[Frame]]:
        self.running = False
        return [[self._frame(Comm.STOP)]]

    @property
    def silence_limit(self) -> float:
        return max(3 * self.config.heartbeat_period, 0.05)
