"""The controller process: hardware interface + controllers + Zenoh, one loop.

Each cycle: exchange with the hardware (setpoints out, feedback in), report
faults to the trajectory controller (which aborts and holds) and as diagnostics, run the
controller, publish joint states, feedback and results, and record the cycle
(published in batches as ``hil_msgs/ControlSamples``). Real-time mode paces
the cycle (hil.realtime.CyclePacer: SCHED_FIFO where allowed) and keeps period
statistics; lock-step mode runs the next cycle as soon as the hardware
answered, with the controller's clock advancing one period per cycle.
"""

from __future__ import annotations

import math
import queue
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

import zenoh

from hil.controllers import Defaults, JointTrajectoryController
from hil.controllers.joint_state import JointStateBroadcaster
from hil.hardware import AxisFault, HardwareInterface
from hil.messaging.diagnostics import DiagnosticStatus, fault_values
from hil.messaging.samples import ControlSampleBuffer
from hil.messaging.zenoh_api import (
    ControlSamplesPublisher, DiagnosticsPublisher, JointStatePublisher, TrajectoryActionServer,
    key,
)
from hil.realtime import REAL_TIME_PRIORITY, CyclePacer, PeriodStatistics


class RosFace(Protocol):
    """What the control loop hands a ROS 2 face (:mod:`hil.messaging.ros.face`): CDR bytes
    it already encoded for hil's own keys, and the goals that ended. It is called from
    the control loop: each call must take microseconds."""

    def publish_joint_states(self, payload: bytes) -> None: ...
    def publish_feedback(self, payload: bytes) -> None: ...
    def publish_diagnostics(self, payload: bytes) -> None: ...
    def record_results(self, finished: list) -> None: ...
    def close(self) -> None: ...


#: how long a fault reset may take to bring every drive back (s)
RESET_TIMEOUT = 10.0


@dataclass
class FaultResetRequest:
    """A fault reset asked for from another thread; the control loop fills in the answer."""

    done: threading.Event = field(default_factory=threading.Event)
    succeeded: bool = False
    message: str = ""
    deadline: float = 0.0


class ControlNode:
    """Runs the control loop until :meth:`stop`."""

    def __init__(self, hardware: HardwareInterface, session: zenoh.Session, cycle_hz: float,
                 lock_step: bool = False, joint_state_hz: float = 100.0,
                 feedback_hz: float = 20.0, samples_hz: float = 10.0,
                 defaults: Defaults = Defaults(), priority: int = REAL_TIME_PRIORITY,
                 ros: Callable[[ControlNode], RosFace] | None = None):
        """``priority``: the real-time loop's SCHED_FIFO priority where allowed (0: none).
        ``ros``: makes the node's ROS 2 face (joint states, feedback, results and
        diagnostics go to it as well as to hil's keys); None: no ROS face."""
        self.hardware = hardware
        robot = hardware.robot
        self.period = 1.0 / cycle_hz
        self.lock_step = lock_step
        self.priority = priority
        self.controller = JointTrajectoryController(robot, defaults)
        self.broadcaster = JointStateBroadcaster(robot, hardware.joint_names)
        self._cycle = 0
        self._start = time.monotonic()
        self.server = TrajectoryActionServer(session, robot.name, self.controller, self.clock)
        self.joint_states = JointStatePublisher(session, robot.name)
        self.samples = ControlSampleBuffer(hardware.joint_names, hardware.actuator_names,
                                           self.period, max(1, round(cycle_hz / samples_hz)))
        self.sample_publisher = ControlSamplesPublisher(session, robot.name)
        self.diagnostics = DiagnosticsPublisher(session, robot.name)
        self._session = session
        self._token = None      # declared once the hardware follows commands
        self._every_states = max(1, round(cycle_hz / joint_state_hz))
        self._every_feedback = max(1, round(cycle_hz / feedback_hz))
        # publications on different cycles where the rates allow (joint states halfway, the
        # feedback a third into their periods, sample batches on full buffers): each costs
        # tens to a hundred microseconds, and stacked on one cycle they would overrun it
        self._states_phase = self._every_states // 2
        self._feedback_phase = self._every_feedback // 3
        self.statistics = PeriodStatistics(self.period)
        self.faults: list[AxisFault] = []
        self._stop = threading.Event()
        self._resets: queue.SimpleQueue[FaultResetRequest] = queue.SimpleQueue()
        self._reset: FaultResetRequest | None = None
        self.server.on_reset = self.reset_faults
        self.ros = ros(self) if ros is not None else None

    def figures(self) -> dict:
        """The run so far: period statistics (real time), the hardware's round trips (SYNC
        out to the last answer in, where it measures them), and the faults reported."""
        figures = self.statistics.figures() if self.statistics.count else {"cycles": 0}
        round_trips = getattr(self.hardware, "round_trips", None)
        if round_trips is not None:
            figures.update(round_trips.percentiles_us("round_trip"))
        figures["faults"] = [str(fault) for fault in self.faults]
        return figures

    def summary(self) -> str:
        """One line of :meth:`figures`."""
        line = self.statistics.summary() if not self.lock_step else f"{self._cycle} cycles"
        round_trips = getattr(self.hardware, "round_trips", None)
        if round_trips is not None and round_trips.count:
            trips = round_trips.percentiles_us("rt")
            line += f"; round trip p50 {trips['rt_p50_us']:.0f} us, p99 {trips['rt_p99_us']:.0f} us"
        return line

    @property
    def cycling(self) -> bool:
        """Whether the bring-up is done and the loop runs its cycles."""
        return self._token is not None

    @property
    def cycles(self) -> int:
        """Cycles run so far."""
        return self._cycle

    def clock(self) -> float:
        """The controller's time: cycles x period in lock-step, monotonic otherwise."""
        return self._cycle * self.period if self.lock_step else time.monotonic() - self._start

    def stop(self) -> None:
        self._stop.set()

    def reset_faults(self, timeout: float = RESET_TIMEOUT) -> tuple[bool, str]:
        """Reset the hardware's faults and accept goals again, holding where the joints are.

        Blocks until every drive follows commands again (True), or a fault persists or
        ``timeout`` passes (False, with why). Safe to call from any thread.
        """
        request = FaultResetRequest()
        self._resets.put(request)
        if not request.done.wait(timeout + 1.0):
            return False, "the control loop did not answer (is it running?)"
        return request.succeeded, request.message

    def run(self) -> None:
        hardware = self.hardware
        pacer = None
        try:
            start = hardware.start()
            self.controller.update(self.clock(), start.positions, start.velocities)
            self._token = self._session.liveliness().declare_token(
                key(self.hardware.robot.name, "control"))
            pacer = None if self.lock_step else CyclePacer(self.period, self.statistics,
                                                           self.priority)
            while not self._stop.is_set():
                if pacer is not None:
                    pacer.release()
                if self._reset is None and not self._resets.empty():
                    self._begin_reset()
                feedback = hardware.read()
                self._cycle += 1
                faults = hardware.faults()
                for fault in faults:
                    self.faults.append(fault)
                    self.controller.abort(str(fault))
                    self._diagnose("ERROR", str(fault), fault_values(fault))
                if self._reset is not None:
                    self._advance_reset(faults)
                now = self.clock()
                command, velocity = self.controller.update(now, feedback.positions,
                                                           feedback.velocities)
                hardware.write(command, velocity)
                self.samples.add(self._cycle, now, command, velocity, feedback,
                                 pacer.last_period if pacer is not None else math.nan,
                                 getattr(hardware, "last_round_trip", math.nan))
                self._publish(feedback)
        finally:
            if pacer is not None:
                pacer.close()      # shutting down is not real-time work
            if self._reset is not None:
                self._finish_reset(False, "the controller is shutting down")
            while not self._resets.empty():
                self._resets.get_nowait().done.set()
            self.controller.abort("the controller is shutting down")
            self._publish_results()
            hardware.stop()
            self._publish_samples()
            self.server.close()
            self.joint_states.close()
            self.sample_publisher.close()
            self.diagnostics.close()
            if self.ros is not None:
                self.ros.close()
            if self._token is not None:
                self._token.undeclare()

    def _begin_reset(self) -> None:
        self._reset = self._resets.get_nowait()
        if self.controller.fault is None and self.hardware.ready:
            self._finish_reset(True, "no fault to reset")     # and an active goal runs on
            return
        self._reset.deadline = time.monotonic() + RESET_TIMEOUT
        self.hardware.reset_faults()

    def _advance_reset(self, faults: list[AxisFault]) -> None:
        """Called each cycle of a reset: done when the hardware is ready, failed on a fault."""
        if faults:
            self._finish_reset(False, "; ".join(map(str, faults)))
        elif self.hardware.ready:
            self.controller.clear_fault()
            self._finish_reset(True, "every drive follows commands again; holding position")
            self._diagnose("OK", "fault reset: every drive follows commands again")
        elif time.monotonic() > self._reset.deadline:
            self._finish_reset(False, f"drives not back within {RESET_TIMEOUT:g} s")
            self._diagnose("ERROR", f"fault reset failed: drives not back within "
                                    f"{RESET_TIMEOUT:g} s")

    def _diagnose(self, level: str, message: str,
                  values: tuple[tuple[str, str], ...] = ()) -> None:
        payload = self.diagnostics.publish(DiagnosticStatus(
            level, message, time.time(), self.clock(), hardware_id=self.hardware.robot.name,
            values=values))
        if self.ros is not None:
            self.ros.publish_diagnostics(payload)

    def _finish_reset(self, succeeded: bool, message: str) -> None:
        request, self._reset = self._reset, None
        request.succeeded, request.message = succeeded, message
        request.done.set()

    def _publish(self, feedback) -> None:
        if self._cycle % self._every_states == self._states_phase:
            positions, velocities, efforts = self.broadcaster.compute(
                feedback.positions, feedback.velocities, feedback.efforts)
            payload = self.joint_states.publish(time.time(), self.broadcaster.names, positions,
                                                velocities, efforts)
            if self.ros is not None:
                self.ros.publish_joint_states(payload)
        if self._cycle % self._every_feedback == self._feedback_phase:
            payload = self.server.publish_feedback()
            if payload is not None and self.ros is not None:
                self.ros.publish_feedback(payload)
        self._publish_results()
        if self.samples.full:
            self._publish_samples()

    def _publish_results(self) -> None:
        finished = self.controller.finished()
        if finished:
            self.server.publish_results(finished)
            if self.ros is not None:
                self.ros.record_results(finished)

    def _publish_samples(self) -> None:
        batch = self.samples.take()
        if batch is not None:
            self.sample_publisher.publish(batch)
