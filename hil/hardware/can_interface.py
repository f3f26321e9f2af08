"""The CAN master: :class:`CanHardwareInterface`, for the drives of a bus config, whatever
their families.

Each drive is an axis of its protocol (:mod:`hil.hardware.axis`: CiA 402, ODrive CANSimple,
MIT, Damiao, CubeMars, ...); the master composes what it does with them, one job each:
:class:`~hil.hardware.bring_up.BringUp` brings them up (boot, configure, enable),
:class:`~hil.hardware.exchange.CycleExchange` runs the cycles on the buses (a cycle's frames
out, its answers in), :class:`~hil.hardware.watch.FaultWatch` reports faults and silences
(naming the node and joints, quick-stopping every axis) and resets them, and
:class:`~hil.hardware.mapping.JointMapping` maps joint space to actuator space and back
through the robot's transmissions.
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable

import can
import numpy as np

from hil.bus_config.sensor_types import ImuConfig
from hil.bus_config.types import SystemConfig
from hil.can import watch_deliveries
from hil.hardware.axis import AxisFault
from hil.hardware.bring_up import BOOT_TIMEOUT, BringUp
from hil.hardware.can_force_torque import CanForceTorque
from hil.hardware.can_imu import CanImu, PolledCanImu
from hil.hardware.exchange import MISSED_ANSWER_LIMIT, CycleExchange
from hil.hardware.feedback import JointFeedback
from hil.hardware.interface import HardwareInterface
from hil.hardware.mapping import JointMapping
from hil.hardware.sensor_states import ImuDescription, ImuState, WrenchState
from hil.hardware.serial_imu import SerialImu
from hil.hardware.watch import FaultWatch
from hil.realtime.stalls import Stall

log = logging.getLogger(__name__)


class CanHardwareInterface(HardwareInterface):
    """The CAN master of every drive of a bus config, each spoken to in its own protocol.

    A cycle is :meth:`read` (the answers to the last cycle's frames), the controllers, then
    :meth:`write` (this cycle's frames, each bus' ended as its protocols ask: CANopen's
    SYNC): the answers travel while the loop sleeps, and a cycle's work does not wait for
    them. They are due ``reply_timeout`` after the frames left (one period in real time);
    read waits for what is still missing until then."""

    silence_cycles = MISSED_ANSWER_LIMIT + 1

    def __init__(self, config: SystemConfig, buses: dict[str, can.BusABC],
                 reply_timeout: float | None = None, boot_timeout: float = BOOT_TIMEOUT):
        """``boot_timeout``: how long :meth:`start` waits for every drive to boot (s): a
        CANopen master waits for its slaves' boot-up (CiA 302), whichever starts first."""
        super().__init__(config.robot)
        self.config = config
        self.boot_timeout = boot_timeout
        self.reply_timeout = reply_timeout if reply_timeout is not None else 1.0 / config.cycle_hz
        self._buses = buses
        self._exchange = CycleExchange(config, buses, self.reply_timeout)
        self.axes = self._exchange.axes
        self.actuator_names = tuple(a.config.actuator for a in self.axes)
        self._mapping = JointMapping(config.robot, self.joint_names, self.axes)
        #: joints (joint_names order) <-> actuators (axes order) in one map
        self.transmissions = self._mapping.transmissions
        self._watch = FaultWatch(self._exchange)
        #: how long a drive may be unheard before it counts as silent (s)
        self.answer_silence_limit = self._watch.answer_silence_limit
        #: each cycle's round trip (s): its last frame sent to its last answer in
        self.round_trips = self._exchange.round_trips
        #: the round trip of the cycle :meth:`read` last took (s; NaN: not every answer came)
        self.last_round_trip = math.nan
        #: the bus config's IMUs, read off their ports or buses
        self.sensors: list[SerialImu | CanImu | PolledCanImu] = [
            _imu_reader(sensor, config.cycle_hz) for sensor in config.imus]
        self.imus = tuple(ImuDescription.of(sensor) for sensor in config.imus)
        # hil control is the Net F/Ts' master: each polled at its poll_hz, in cycles
        self._force_torques = [CanForceTorque(sensor, _cycles_per_poll(config.cycle_hz,
                                                                       sensor.poll_hz))
                               for sensor in config.force_torques]
        self.force_torques = tuple((s.name, s.link) for s in config.force_torques)
        #: the sensors on a bus, listening there once its router runs (start)
        self._bus_sensors: list[CanImu | PolledCanImu | CanForceTorque] = [
            *(s for s in self.sensors if not isinstance(s, SerialImu)), *self._force_torques]
        self._sensor_problems: dict[str, str | None] = {}

    def start(self, cancel: threading.Event | None = None) -> JointFeedback:
        feedback = BringUp(self._exchange, self._watch, self._buses, self.boot_timeout).run(
            self._holding_cycle, len(self.joint_names), cancel)
        routers = self._exchange.routers          # opened by the bring-up
        for sensor in self._bus_sensors:
            if not sensor.attached:
                sensor.attach(routers[sensor.config.bus])
        return feedback

    def _holding_cycle(self, hold: np.ndarray, watch: bool) -> JointFeedback:
        self.write(hold, np.zeros_like(hold), enabling=True)
        return self.read(watch)

    # --- cyclic ------------------------------------------------------------------------------

    def read(self, watch: bool = True) -> JointFeedback:
        """The answers to the last cycle's frames: waited for until ``reply_timeout`` after
        them; with ``watch``, missing answers, faults and silences are reported
        (:meth:`faults`)."""
        self.last_round_trip = self._exchange.await_answers(skip_silent=watch)
        fault_watch = self._watch
        if watch:
            fault_watch.watch()
        if fault_watch.recovering:
            fault_watch.settle()
        feedback, implausible = self._mapping.joint_feedback()
        for joint, fault in implausible:
            fault_watch.report(joint, "implausible", fault)
        return feedback

    def write(self, positions, velocities, enabling: bool = False) -> None:
        """This cycle's frames of every axis (walking it toward following ``positions``, or
        holding where it is while ``enabling`` or recovering), each bus' cycle-end frames
        last."""
        targets, speeds, torques = self._mapping.actuator_commands(positions, velocities)
        fault_watch = self._watch
        self._exchange.send(targets, speeds, torques, fault_watch.stopping,
                            enabling or fault_watch.recovering)

    # --- faults -----------------------------------------------------------------------------

    def faults(self) -> list[AxisFault]:
        return self._watch.faults()

    @property
    def stopping(self) -> bool:
        return self._watch.stopping

    def reset_faults(self) -> None:
        """Fault-reset faulted drives, disable quick-stopped ones, and enable them all again at
        standstill (a rebooted drive configured again first). A fault that persists (a silent
        drive, a fault still present) is reported again by the next cycles."""
        self._watch.reset()

    @property
    def ready(self) -> bool:
        return self._watch.ready

    def stop(self) -> None:
        """Disable every drive (each in its protocol's way), then release the buses and the
        sensors' ports."""
        self._exchange.close()
        for sensor in [*self.sensors, *self._force_torques]:
            sensor.close()

    def answer_deadlines(self) -> dict[tuple[str, int], float]:
        return {(bus.name, drive.node_id): drive.watchdog_timeout
                for bus in self.config.buses for drive in bus.drives}

    def watch_transport(self, on_stall: Callable[[Stall], None]) -> None:
        watch_deliveries(self._buses.values(), on_stall)

    def read_sensors(self) -> list[ImuState | WrenchState]:
        states: list[ImuState | WrenchState] = []
        for sensor in self._bus_sensors:
            sensor.request(self._exchange.cycle)
        for force_torque in self._force_torques:
            states += force_torque.poll()
        for sensor in self.sensors:
            states += sensor.poll()
            name = sensor.config.name
            if sensor.problem != self._sensor_problems.get(name, "not opened yet"):
                self._sensor_problems[name] = sensor.problem
                if sensor.problem is None:
                    log.info("sensor '%s': read", name)
                else:
                    log.warning("sensor '%s' is not read: %s", name, sensor.problem)
        return states


def _imu_reader(sensor: ImuConfig, cycle_hz: float) -> SerialImu | CanImu | PolledCanImu:
    """Its product's reader: WitMotion's off its serial port, HiPNUC's TPDOs off its bus, a
    DM-IMU polled on its bus."""
    if sensor.product == "wit":
        return SerialImu(sensor)
    if sensor.product == "hipnuc":
        return CanImu(sensor)
    return PolledCanImu(sensor, _cycles_per_poll(cycle_hz, sensor.poll_hz))


def _cycles_per_poll(cycle_hz: float, poll_hz: float) -> int:
    """A sensor polled at ``poll_hz`` is asked every this many control cycles."""
    return max(1, round(cycle_hz / poll_hz))
