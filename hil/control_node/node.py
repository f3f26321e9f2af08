"""The control loop: hardware interface + controllers, and the faces that carry its outputs.

Each cycle: exchange with the hardware (setpoints out, feedback in), report faults to the
trajectory controller (which aborts and holds) and as diagnostics, run the controller,
publish joint states, feedback and results, and record the cycle (published in batches as
``hil_msgs/ControlSamples``). Real-time mode paces the cycle
(:class:`hil.realtime.CyclePacer`: SCHED_FIFO where allowed) and keeps period statistics;
lock-step mode runs the next cycle as soon as the hardware answered, with the controller's
clock advancing one period per cycle.
"""

from __future__ import annotations

import logging
import math
import queue
import threading
import time
from collections.abc import Callable, Sequence

import zenoh

from hil.control_node.attribution import GRACE, Attribution, FaultAttribution
from hil.control_node.bring_up import judged_bring_up
from hil.control_node.fault_reset import RESET_TIMEOUT, FaultReset
from hil.controllers.config import DEFAULT_GOAL_TOLERANCE, ControllersConfig, hil_controllers
from hil.controllers.manager import ControllerManager
from hil.controllers.joint_state import JointStateBroadcaster
from hil.hardware import AxisFault, HardwareInterface
from hil.hardware.feedback import JointFeedback
from hil.messaging import cdr
from hil.messaging.action import feedback_message
from hil.messaging.diagnostics import DiagnosticStatus, fault_values
from hil.messaging.face import ControlFace, ZenohControlFace
from hil.messaging.keys import IMU, WRENCH, key
from hil.messaging.samples import ControlSampleBuffer
from hil.messaging.zenoh_api import StallPublisher, StallSubscriber
from hil.realtime import REAL_TIME, REAL_TIME_PRIORITY, CyclePacer, PeriodStatistics, Timing
from hil.realtime.stalls import Stall, StallDetector, StallTally

log = logging.getLogger(__name__)

#: makes a face of the node (a ROS 2 node, say) once the node has its controller and clock
FaceFactory = Callable[["ControlNode"], ControlFace]


class ControlNode:
    """Runs the control loop until :meth:`stop`."""

    def __init__(self, hardware: HardwareInterface, session: zenoh.Session, cycle_hz: float,
                 timing: Timing = REAL_TIME, joint_state_hz: float = 100.0,
                 samples_hz: float = 10.0, controllers: ControllersConfig | None = None,
                 priority: int = REAL_TIME_PRIORITY, faces: Sequence[FaceFactory] = ()):
        """``controllers``: what the controller manager runs (None: hil's own set,
        :func:`hil.controllers.config.hil_controllers`); the trajectory controller's feedback
        goes out at its action_monitor_rate. ``priority``: the real-time loop's SCHED_FIFO
        priority where allowed (0: none). The node always has its face on hil's own keys in
        ``session``; ``faces`` make more (the ROS 2 face), each given every output too."""
        self.hardware = hardware
        robot = hardware.robot
        self.period = 1.0 / cycle_hz
        self.timing = timing
        self.lock_step = timing.lock_step
        self.priority = priority
        if controllers is None:
            controllers = hil_controllers(hardware.joint_names, DEFAULT_GOAL_TOLERANCE)
        #: the controllers, listed and switched as controller_manager does
        self.manager = ControllerManager.from_config(robot, hardware.joint_names, controllers,
                                                     self.period)
        #: the joint trajectory controller (its action faces serve it)
        self.controller = self.manager.trajectory
        feedback_hz = controllers.trajectory.action_monitor_rate
        self.broadcaster = JointStateBroadcaster(robot, hardware.joint_names)
        self._joint_states = cdr.JointStateCdr(self.broadcaster.names)
        self._cycle = 0
        self._start = time.monotonic()
        self.samples = ControlSampleBuffer(hardware.joint_names, hardware.actuator_names,
                                           self.period, max(1, round(cycle_hz / samples_hz)))
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
        self._fault_reset = FaultReset(hardware, self.controller, self._diagnose)
        self.faces: list[ControlFace] = [ZenohControlFace(
            session, robot.name, self.manager, self.stamp_to_clock, self.reset_faults)]
        self.faces += [make(self) for make in faces]
        #: each sensor's message (sensor_msgs/Imu, geometry_msgs/WrenchStamped), packed in
        #: the loop as its samples arrive
        self._sensors: dict[str, cdr.ImuCdr | cdr.WrenchCdr] = {
            **{imu.name: cdr.ImuCdr(imu.frame, imu.variances) for imu in hardware.imus},
            **{name: cdr.WrenchCdr(frame) for name, frame in hardware.force_torques}}
        declared = tuple((imu.name, IMU) for imu in hardware.imus) + tuple(
            (name, WRENCH) for name, _ in hardware.force_torques)
        for face in self.faces:
            face.declare_sensors(declared)
        #: faults explained by the bench's own stalls (real time), as diagnosed
        self.bench_faults: list[Attribution] = []
        #: the control loop's own stalls (real time)
        self.stalls = StallDetector("control", self.period)
        #: every stall of the bench heard of since the loop cycles (the loop's own, the
        #: simulator's, the transport's), by process
        self.bench_stalls = StallTally()
        self._attribution = FaultAttribution(self.period, hardware.silence_cycles,
                                             hardware.answer_deadlines())
        self._reported_stalls: queue.SimpleQueue[Stall] = queue.SimpleQueue()
        self._cycling_since = math.inf            # wall time; stalls before it are not counted
        self._stopped_cycling: float | None = None
        # one path for every stall, this process' own too: published (for hil up and the
        # recording) and heard back with the others'
        self._stall_publisher = self._stall_subscriber = None
        if not timing.lock_step:
            self._stall_publisher = StallPublisher(session, robot.name)
            self._stall_subscriber = StallSubscriber(
                session, robot.name, self._reported_stalls.put, log.warning)
            hardware.watch_transport(self._stall_publisher.publish)

    def figures(self) -> dict:
        """The run so far: period statistics (real time) or cycles, seconds cycling and
        speed-up over real time (lock-step), the hardware's round trips (SYNC out to the last
        answer in, where it measures them), and the faults reported."""
        figures = self.statistics.figures() if self.statistics.count else {"cycles": 0}
        if self.lock_step:      # no pacing: the speed is what the run is about
            cycling = max(0.0, (self._stopped_cycling or time.time()) - self._cycling_since)
            figures.update({"cycles": self._cycle, "cycling_seconds": cycling,
                            "speedup_over_real_time": self._cycle * self.period / cycling
                            if cycling > 0 else 0.0})
        round_trips = self.hardware.round_trips
        if round_trips is not None:
            figures.update(round_trips.percentiles_us("round_trip"))
        figures["faults"] = [str(fault) for fault in self.faults]
        figures["bench_faults"] = [attribution.message() for attribution in self.bench_faults]
        figures["stalls"] = self.bench_stalls.figures()
        return figures

    def summary(self) -> str:
        """One line of :meth:`figures`."""
        line = (f"{self.statistics.summary()}; {self.bench_stalls.summary()}"
                if not self.lock_step else f"{self._cycle} cycles")
        round_trips = self.hardware.round_trips
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

    def stamp_to_clock(self, stamp: float) -> float:
        """A goal's header stamp (wall time, as hil's keys stamp everything; the ROS face
        maps the plant's time with use_sim_time) on the controller's clock."""
        return self.clock() + (stamp - time.time())

    def stop(self) -> None:
        self._stop.set()

    @property
    def stopping(self) -> bool:
        """Whether :meth:`stop` was called."""
        return self._stop.is_set()

    def reset_faults(self, timeout: float = RESET_TIMEOUT) -> tuple[bool, str]:
        """Reset the hardware's faults and accept goals again, holding where the joints are.

        Blocks until every drive follows commands again (True), or a fault persists or
        ``timeout`` passes (False, with why). Safe to call from any thread.
        """
        return self._fault_reset.request(timeout)

    def run(self) -> None:
        pacer = None
        try:
            start = self._bring_up()
            self.manager.update(self.clock(), start.positions, start.velocities)
            self._token = self._session.liveliness().declare_token(
                key(self.hardware.robot.name, "control"))
            self._cycling_since = time.time()
            pacer = None if self.lock_step else CyclePacer(self.period, self.statistics,
                                                           self.priority)
            while not self._stop.is_set():
                if pacer is not None:
                    pacer.release()
                self._cycle_once(pacer)
            self._stopped_cycling = time.time()
        finally:
            if pacer is not None:
                pacer.close()      # shutting down is not real-time work
            self._shut_down()

    def _bring_up(self) -> JointFeedback:
        """The hardware's start; in real time judged against the bench's stalls meanwhile."""
        if self._stall_publisher is None:       # lock-step: no stall fails it
            return self.hardware.start(self._stop)
        return judged_bring_up(lambda: self.hardware.start(self._stop),
                               self._stall_publisher.publish, self._heard_stalls,
                               self._stop.is_set)

    def _heard_stalls(self) -> list[Stall]:
        heard = []
        while not self._reported_stalls.empty():
            heard.append(self._reported_stalls.get_nowait())
        return heard

    def _cycle_once(self, pacer: CyclePacer | None) -> None:
        """One cycle: read, faults, the controller, write, record, publish."""
        hardware = self.hardware
        released = time.time()
        self._fault_reset.begin()
        feedback = hardware.read()
        self._cycle += 1
        faults = hardware.faults()
        for fault in faults:
            self.faults.append(fault)
            self.controller.abort(str(fault))
            self.manager.hold(feedback.positions)
            self._diagnose("ERROR", str(fault), fault_values(fault))
            self._attribution.fault(fault, time.time())
        self._fault_reset.advance(faults)
        if pacer is not None:
            self._attribute(pacer, released)
        now = self.clock()
        command, velocity = self.manager.update(now, feedback.positions, feedback.velocities)
        hardware.write(command, velocity)
        self.samples.add(self._cycle, now, command, velocity, feedback,
                         pacer.last_period if pacer is not None else math.nan,
                         hardware.last_round_trip)
        self._publish(feedback)

    def _attribute(self, pacer: CyclePacer, released: float) -> None:
        """Real time: note the loop's own stall (it ended at this cycle's release, wall time
        ``released``) and the bench's reported ones; diagnose the silent drives a stall
        explains (after the fault itself: the reaction stays)."""
        own = self.stalls.late(pacer.last_period - self.period, released)
        if own is not None:
            self._stall_publisher.publish(own)
        self._attribute_waiting_faults()

    def _attribute_waiting_faults(self) -> None:
        """The stalls reported since, held against the faults that wait for them."""
        while not self._reported_stalls.empty():
            stall = self._reported_stalls.get_nowait()
            if stall.end >= self._cycling_since:    # not the bring-up's
                self.bench_stalls.add(stall)
                self._attribution.stall(stall)
        if self._attribution.waiting:
            for attribution in self._attribution.attributions(time.time()):
                self.bench_faults.append(attribution)
                self._diagnose("WARN", attribution.message(), attribution.values())

    def _attribute_at_the_end(self) -> None:
        """Real time, the drives stopped: faults still in their grace get it (the reports of
        stalls in flight are waited for, at most GRACE), so that a run ending right after
        a stall does not leave the faults it caused unexplained."""
        if self.lock_step or not self._attribution.waiting:
            return
        time.sleep(max(0.0, min(GRACE, self._attribution.settled_at() - time.time())))
        self._attribute_waiting_faults()

    def _shut_down(self) -> None:
        """After the last cycle: fail a reset under way, abort the goal, disable the drives,
        publish what is left, close the faces."""
        self._fault_reset.close()
        self.controller.abort("the controller is shutting down")
        self._publish_results()
        self.hardware.stop()
        self._attribute_at_the_end()
        self._publish_samples()
        for face in self.faces:
            face.close()
        for stalls in (self._stall_subscriber, self._stall_publisher):
            if stalls is not None:
                stalls.close()
        if self._token is not None:
            self._token.undeclare()

    def _diagnose(self, level: str, message: str,
                  values: tuple[tuple[str, str], ...] = ()) -> None:
        payload = DiagnosticStatus(level, message, time.time(), self.clock(),
                                   hardware_id=self.hardware.robot.name, values=values).encode()
        for face in self.faces:
            face.publish_diagnostics(payload)

    def _publish(self, feedback: JointFeedback) -> None:
        if self._cycle % self._every_states == self._states_phase:
            positions, velocities, efforts = self.broadcaster.compute(
                feedback.positions, feedback.velocities, feedback.efforts)
            payload = self._joint_states.encode(time.time(), positions, velocities, efforts)
            for face in self.faces:
                face.publish_joint_states(payload)
        if self._cycle % self._every_feedback == self._feedback_phase:
            state = self.controller.state()
            if state.goal_id is not None:
                payload = cdr.encode(feedback_message(state, time.time()))
                for face in self.faces:
                    face.publish_feedback(payload, state)
        self._publish_results()
        if self.samples.full:
            self._publish_samples()
        if self._sensors:
            self._publish_sensors()

    def _publish_sensors(self) -> None:
        """The sensors' samples read since the last cycle, each as it came (as ros2_controllers'
        imu_sensor_broadcaster and force_torque_sensor_broadcaster publish their sensor's
        state every update)."""
        for state in self.hardware.read_sensors():
            encoder = self._sensors[state.sensor]
            if isinstance(encoder, cdr.WrenchCdr):
                payload = encoder.encode(state.received, state.force, state.torque)
            else:
                reading = state.reading
                payload = encoder.encode(state.received, reading.orientation,
                                         reading.angular_velocity, reading.acceleration)
            for face in self.faces:
                face.publish_sensor(state.sensor, payload)

    def _publish_results(self) -> None:
        finished = self.controller.finished()
        if finished:
            for face in self.faces:
                face.publish_results(finished)

    def _publish_samples(self) -> None:
        batch = self.samples.take()
        if batch is not None:
            for face in self.faces:
                face.publish_samples(batch)
