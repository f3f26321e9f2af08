"""The CAN master: :class:`CanHardwareInterface`, for the drives of a bus config.

It brings every drive up (NMT, SDO, 402 state machine to OPERATION ENABLED in cyclic
synchronous position mode), and each cycle sends the setpoints by RPDO, produces SYNC on
every bus and collects the TPDO feedback, mapping actuator space to joint space through the
robot's transmissions. It watches heartbeats, EMCY and missing TPDOs; any fault or silence
is reported with the node id and joint and quick-stops every axis.
"""

from __future__ import annotations

import itertools
import logging
import math
import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

import can
import numpy as np

from hil.bus_config.types import SystemConfig
from hil.can import batching, sent_together, watch_deliveries
from hil.errors import HilError
from hil.hardware.axis import Axis, AxisFault, FaultKind, command_of
from hil.hardware.feedback import JointFeedback, PlausibilityCheck
from hil.hardware.gravity import GravityModel
from hil.hardware.hold_ups import not_enabled, slow_links, unreached_links
from hil.hardware.interface import HardwareInterface
from hil.protocols import protocol
from hil.realtime import PeriodStatistics, Ring
from hil.realtime.stalls import Stall
from hil.transmissions import TransmissionStack, build_transmissions

if TYPE_CHECKING:
    from hil.can.network import CanopenNetwork

log = logging.getLogger(__name__)

#: how long a bring-up waits for every drive's boot-up by default (s): hil up starts the
#: controller once its sim runs; ``hil control`` alone waits longer (its --boot-timeout)
BOOT_TIMEOUT = 3.0
#: while waiting for drives, who is still missing is logged this often (s)
BOOT_REPORT_EVERY = 5.0
#: a drive not heard since its reset is reset again this often (s), as a CiA 302 master
#: retries a slave's boot: its boot-up may have been sent before the link to it was up
BOOT_RETRY_EVERY = 1.0
ENABLE_TIMEOUT = 10.0
MISSED_ANSWER_LIMIT = 5
#: lock-step's wait for a cycle's answers (s): time stands still while nobody answers, so this
#: only has to tell a slow peer (a loaded machine, User-Mode Linux) from a dead one
LOCK_STEP_REPLY_TIMEOUT = 2.0
#: CiA 301's SYNC COB-ID, sent on every bus with a protocol that uses it
SYNC_ID = 0x080


class CanHardwareInterface(HardwareInterface):
    """CAN master for every drive of a bus config, each spoken to in its own protocol.

    A cycle is :meth:`read` (the answers to the last SYNC), the controllers, then
    :meth:`write` (setpoints and SYNC): the answers travel while the loop sleeps, and a
    cycle's work does not wait for them. The answers to a SYNC are due before the next one,
    ``reply_timeout`` after it (one period in real time); read waits for what is still
    missing until then."""

    def __init__(self, config: SystemConfig, buses: dict[str, can.BusABC],
                 reply_timeout: float | None = None, boot_timeout: float = BOOT_TIMEOUT):
        """``boot_timeout``: how long :meth:`start` waits for every drive to boot (s): a
        CANopen master waits for its slaves' boot-up (CiA 302), whichever starts first."""
        super().__init__(config.robot)
        self.config = config
        self.boot_timeout = boot_timeout
        self.reply_timeout = reply_timeout if reply_timeout is not None else 1.0 / config.cycle_hz
        self._buses = buses
        self._networks: dict[str, CanopenNetwork] = {}
        self.axes: list[Axis] = [protocol(drive.protocol).axis_class()(drive, bus.name,
                                                                       self._on_feedback)
                                 for bus in config.buses for drive in bus.drives]
        self._sync_buses = sorted({a.bus_name for a in self.axes if a.protocol.uses_sync})
        self._all_heard = False
        self.actuator_names = tuple(a.config.actuator for a in self.axes)
        # joints (joint_names order) <-> actuators (axes order) in one map
        self.transmissions = TransmissionStack(build_transmissions(config.robot),
                                               self.joint_names, self.actuator_names)
        self._gravity_axes = [a.config.torque_feed_forward == "gravity" for a in self.axes]
        self._gravity = (GravityModel(config.robot, self.joint_names)
                         if any(self._gravity_axes) else None)
        self._no_torques = [0.0] * len(self.axes)
        self._cycle = 0
        self._stopping = False
        self._recovering = False
        self._reset_cycle = 0          # the cycle reset_faults() was called in
        self._reported: set[tuple[str, str]] = set()
        #: rebooted axes being configured again (a reset's), off the watch meanwhile
        self._configuring: set[Axis] = set()
        self._pending: list[AxisFault] = []
        self._arrived = threading.Condition()
        self._awaiting = False          # a reader is in _await_feedback
        #: how long a drive may be unheard, its answers within the limit of missed ones (in
        #: lock-step a stalled sim is slow, not dead); a bring-up request waits as long (s)
        self.answer_silence_limit = MISSED_ANSWER_LIMIT * self.reply_timeout
        self._plausibility = PlausibilityCheck(config.robot, self.joint_names)
        #: each cycle's round trip (s): its SYNC (last frame) sent to its last answer in
        self.round_trips = Ring(PeriodStatistics.KEEP)
        self._last_answer = 0.0
        self._sync_sent: float | None = None     # perf_counter of the last write's SYNC
        #: the round trip of the cycle :meth:`read` last took (s; NaN: not every answer came)
        self.last_round_trip = math.nan

    # --- bring-up ---------------------------------------------------------------------

    def start(self, cancel: threading.Event | None = None) -> JointFeedback:
        # canopen loads with the first bus (its __init__ imports canopen.node.local as well,
        # whose LocalNode the master never makes), not with the controller's modules
        from hil.can.network import start_network

        for name, bus in self._buses.items():
            self._networks[name] = start_network(bus)
        self._batched = batching(self._buses.values())     # what write sends together
        for axis in self.axes:
            axis.attach(self._networks[axis.bus_name])
        for axis in self.axes:                         # reset: every drive starts afresh
            axis.reset()
        hold = np.zeros(len(self.joint_names))
        began = time.monotonic()
        reported = retried = began
        # cycles run meanwhile (unwatched): some protocols are heard only in answers
        while not all(axis.booted.is_set() for axis in self.axes):
            self.write(hold, np.zeros_like(hold), enabling=True)
            hold = self.read(watch=False).positions
            now = time.monotonic()
            silent = [a.label for a in self.axes if not a.booted.is_set()]
            if silent and now - began > self.boot_timeout:    # a cycle may outlast it
                raise HilError.single(
                    f"{'; '.join(silent)}: not heard within {self.boot_timeout:g} s after "
                    "reset" + unreached_links(self._buses),
                    hint="is `hil sim` (or the real drive) running on this bus, with the same "
                         "node id and protocol?")
            if cancel is not None and cancel.is_set():
                raise HilError.single(f"stopped while waiting for {'; '.join(silent)} to boot")
            if now - retried >= BOOT_RETRY_EVERY:
                retried = now
                for axis in self.axes:
                    if not axis.booted.is_set():
                        axis.reset()
            if now - reported >= BOOT_REPORT_EVERY and silent:
                reported = now
                log.warning("waiting for %d of %d drive(s) to boot (%.0f of %g s): %s",
                            len(silent), len(self.axes), now - began, self.boot_timeout,
                            "; ".join(silent))
        for axis in self.axes:
            self._configure(axis)
        deadline = time.monotonic() + ENABLE_TIMEOUT
        while True:
            self.write(hold, np.zeros_like(hold), enabling=True)
            feedback = self.read()
            hold = feedback.positions
            waiting = [a for a in self.axes if not a.enabled]
            if not waiting:
                break
            # a silence or fault seen while enabling ends the bring-up with what it was
            faults = list(self._pending) + [f for f in map(Axis.fault, waiting) if f]
            if faults or time.monotonic() > deadline:
                raise HilError.single(
                    "drives did not enable: " + "; ".join(
                        [str(f) for f in faults] or [not_enabled(a) for a in waiting])
                    + slow_links(self._buses, self.reply_timeout))
        self._pending.clear()
        return feedback

    # --- cyclic ------------------------------------------------------------------------------

    def read(self, watch: bool = True) -> JointFeedback:
        """The answers to the last SYNC: waited for until ``reply_timeout`` after it; with
        ``watch``, missing answers, faults and silences are reported (:meth:`faults`)."""
        self.last_round_trip = math.nan
        if self._sync_sent is not None:
            deadline = self._sync_sent + self.reply_timeout
            if self._await_feedback(skip_silent=watch, deadline=deadline):
                self.last_round_trip = self._last_answer - self._sync_sent
                self.round_trips.add(self.last_round_trip)
        if watch:
            self._watch()
        if (self._recovering and not self._stopping and not self._configuring
                and all(a.enabled for a in self.axes)):
            self._recovering = False
        return self._checked(self._joint_feedback())

    def write(self, positions, velocities, enabling: bool = False) -> None:
        """This cycle's frames of every axis (walking it toward following ``positions``, or
        holding where it is while ``enabling`` or recovering), then SYNC on every bus."""
        self._cycle += 1
        targets = self.transmissions.joint_to_actuator_position(positions).tolist()
        speeds = self.transmissions.joint_to_actuator_velocity(velocities).tolist()
        torques = self._feed_forward_torques(positions)
        hold = enabling or self._recovering
        # a bus' frames in one send (hil-virtual), SYNC last (after its RPDOs, CiA 301); every
        # bus' in one put where they can (zenoh)
        batches: dict[str, list[tuple[int, bytes, bool]]] = {n: [] for n in self._networks}
        for axis, target, speed, torque in zip(self.axes, targets, speeds, torques):
            axis.begin_cycle(self._cycle)     # a torque only where the protocol carries one
            batches[axis.bus_name] += axis.cycle_frames(
                command_of((target, speed, torque, self._stopping, hold)))
        for name in self._sync_buses:
            batches[name].append((SYNC_ID, b"", False))
        with sent_together(self._batched):
            for name, frames in batches.items():
                self._networks[name].send_in_order(frames)
        self._sync_sent = time.perf_counter()

    def _feed_forward_torques(self, positions) -> list[float]:
        """Each axis' torque feed-forward (N·m, motor side): what holds its joints against
        gravity at ``positions``, for the drives whose config asks (0 for the others)."""
        if self._gravity is None:
            return self._no_torques
        joint_torques = self._gravity.torques(np.asarray(positions, dtype=float).tolist())
        torques = self.transmissions.joint_to_actuator_effort(joint_torques).tolist()
        return [t if wanted else 0.0 for t, wanted in zip(torques, self._gravity_axes)]

    def _await_feedback(self, skip_silent: bool, deadline: float) -> bool:
        """Wait (up to ``deadline``, perf_counter) until every axis' answer of this cycle is
        in; whether they all came.

        With ``skip_silent``, axes already past the missed-answer limit (reported silent) are
        not waited for while any other axis answers: in lock-step a dead drive would hold every
        cycle of the others for the whole timeout (2 s), and their stop with it."""
        cycle = self._cycle
        if not [a for a in self.axes if a.feedback.cycle != cycle]:   # not all() of a generator
            return True          # all in already (lock-step: in this thread), no wait
        awaited = self.axes
        if skip_silent:      # silent as of the last cycle's watch
            awaited = [a for a in self.axes if not _missed_too_many(a, cycle - 1)] \
                or self.axes
        with self._arrived:
            self._awaiting = True
            try:
                return self._arrived.wait_for(
                    lambda: all(a.feedback.cycle == self._cycle for a in awaited),
                    timeout=max(0.0, deadline - time.perf_counter()))
            finally:
                self._awaiting = False

    def _on_feedback(self) -> None:
        self._last_answer = time.perf_counter()
        # a reader sets the flag under the lock before it looks at the answers: an answer
        # that finds it unset was in before that look (no wake-up lost), and one that
        # arrives in the reader's own thread (lock-step) takes no lock
        if self._awaiting:
            with self._arrived:
                self._arrived.notify()

    def _joint_feedback(self) -> JointFeedback:
        feedback = [axis.feedback for axis in self.axes]
        n = len(feedback)
        measured = np.array([f.position for f in feedback] + [f.velocity for f in feedback]
                            + [f.torque for f in feedback])
        joint = self.transmissions.actuator_to_joint_feedback(measured)
        return JointFeedback(joint[:n], joint[n:2 * n], joint[2 * n:], measured[2 * n:],
                             tuple([a.state for a in self.axes]))

    def _checked(self, feedback: JointFeedback) -> JointFeedback:
        """Feedback no joint can produce is a fault, never a joint state (see
        :class:`~hil.hardware.feedback.PlausibilityCheck`)."""
        checked, implausible = self._plausibility.check(feedback, self._heard_joints())
        for k, text in implausible:
            name = self.joint_names[k]
            axis = next(a for a in self.axes if name in a.config.joints)   # its first drive
            self._report(name, "implausible", axis.found(FaultKind.IMPLAUSIBLE, text))
        return checked

    def _heard_joints(self) -> np.ndarray | None:
        """Per joint: all its drives have answered at least once (before that, their values
        are defaults, not measurements); None: every joint's have."""
        # once every drive has answered (from the first cycles on) that stays so
        self._all_heard = self._all_heard or all(axis.feedback.heard for axis in self.axes)
        if self._all_heard:
            return None
        heard = {j: True for j in self.joint_names}
        for axis in self.axes:
            for joint in axis.config.joints:
                heard[joint] = heard.get(joint, True) and axis.feedback.heard
        return np.array([heard[j] for j in self.joint_names])

    # --- faults -----------------------------------------------------------------------------

    def _watch(self) -> None:
        now = time.monotonic()
        # a reset's first answers may be late ones, sampled before its commands reached the
        # drives: the states it walks the drives out of (FAULT, QUICK STOP) count once an
        # answer that late would be silence anyway
        settling = self._recovering and self._cycle - self._reset_cycle <= MISSED_ANSWER_LIMIT
        for axis in self.axes:
            if axis in self._configuring:
                continue
            # a silence is reported once per axis, not once per silent cycle; a drive's own
            # fault once per distinct message
            fault = None if settling else axis.fault(self._stopping)
            if fault is not None:
                self._report(axis.label, fault.message, fault)
            silence = now - axis.last_heard
            if silence > self.answer_silence_limit and silence > axis.silence_limit:
                self._report(axis.label, "heartbeat", axis.found(
                    FaultKind.SILENT, f"is silent: not heard for {silence * 1e3:.0f} ms",
                    silent_for=silence))
            if _missed_too_many(axis, self._cycle):
                missed = self._cycle - axis.feedback.cycle
                self._report(axis.label, "answer", axis.found(
                    FaultKind.SILENT, f"is silent: no answer for {missed} cycles",
                    silent_for=missed * self.reply_timeout))

    def _report(self, subject: str, what: str, fault: AxisFault) -> None:
        """Queue a fault for :meth:`faults` (once per subject and what) and stop every axis."""
        if (subject, what) not in self._reported:
            self._reported.add((subject, what))
            self._pending.append(fault)
            self._stopping = True

    def faults(self) -> list[AxisFault]:
        found, self._pending = self._pending, []
        return found

    @property
    def stopping(self) -> bool:
        return self._stopping

    def reset_faults(self) -> None:
        """Fault-reset faulted drives, disable quick-stopped ones, and enable them all again at
        standstill. A fault that persists (a silent drive, a fault still present) is reported
        again by the next cycles."""
        self._recovering = True
        self._reset_cycle = self._cycle
        self._stopping = False
        self._reported.clear()
        self._pending.clear()
        for axis in self.axes:
            axis.forget_faults()
        rebooted = [a for a in self.axes if a.rebooted and a not in self._configuring]
        if rebooted:
            # SDO takes round trips the control loop must not wait for: the cycles go on
            # (the drives hold), and the reset is done once these follow setpoints too
            self._configuring.update(rebooted)
            threading.Thread(target=self._configure_again, args=(rebooted,),
                             name="configure", daemon=True).start()

    def _configure(self, axis: Axis) -> None:
        axis.request_timeout = self.answer_silence_limit
        axis.configure()
        axis.feedback.cycle = self._cycle    # missed answers count from here on

    def _configure_again(self, axes: list[Axis]) -> None:
        for axis in axes:
            try:
                self._configure(axis)
            except HilError as exc:
                self._report(axis.label, "configure", axis.found(
                    FaultKind.REBOOTED, f"booted again and could not be configured: {exc}"))
            finally:
                self._configuring.discard(axis)

    @property
    def ready(self) -> bool:
        return not (self._stopping or self._recovering or self._configuring)

    def stop(self) -> None:
        """Disable every drive (each in its protocol's way), then release the buses."""
        # each axis' rounds once (MIT's marks the motor as leaving motor mode), sent in step
        rounds = [[(axis.bus_name, frames) for frames in axis.disable_rounds()]
                  for axis in self.axes]
        for step in itertools.zip_longest(*rounds):
            for bus_name, frames in filter(None, step):
                for can_id, data, remote in frames:
                    self._send_quietly(bus_name, can_id, data, remote)
            for name in self._sync_buses:
                self._send_quietly(name, SYNC_ID, b"", False)
            time.sleep(2.0 / self.config.cycle_hz)
        for network in self._networks.values():
            network.notifier.stop(1.0)

    silence_cycles = MISSED_ANSWER_LIMIT + 1

    def answer_deadlines(self) -> dict[tuple[str, int], float]:
        return {(bus.name, drive.node_id): drive.watchdog_timeout
                for bus in self.config.buses for drive in bus.drives}

    def watch_transport(self, on_stall: Callable[[Stall], None]) -> None:
        watch_deliveries(self._buses.values(), on_stall)

    def _send_quietly(self, bus: str, can_id: int, data: bytes, remote: bool) -> None:
        try:
            self._networks[bus].send_message(can_id, data, remote)
        except can.CanError:
            pass


def _missed_too_many(axis: Axis, cycle: int) -> bool:
    """Whether ``axis`` has missed more than MISSED_ANSWER_LIMIT answers by ``cycle``: the
    watch reports it silent, and the cycles after that do not wait for it."""
    return cycle - axis.feedback.cycle > MISSED_ANSWER_LIMIT
