"""Hardware interfaces: what the controllers read and command, in joint space.

:class:`CanHardwareInterface` is a CAN master for the drives of a bus config:
it brings every drive up (NMT, SDO, 402 state machine to OPERATION ENABLED in
cyclic synchronous position mode), and each cycle sends the setpoints by RPDO,
produces SYNC on every bus and collects the TPDO feedback, mapping actuator
space to joint space through the robot's transmissions. It watches heartbeats,
EMCY and missing TPDOs; any fault or silence is reported with the node id and
joint and quick-stops every axis. :class:`FakeHardwareInterface` echoes the
commands as measurements, with no CAN and no physics.
"""

from __future__ import annotations

import threading
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass

import can
import canopen
import numpy as np

from hil.bus_config import SystemConfig
from hil.description import RobotDescription
from hil.drives.cia402 import SYNC_ID   # CiA 301's SYNC COB-ID
from hil.errors import HilError
from hil.hardware.cia402 import DISABLE_VOLTAGE, SHUTDOWN, Cia402Axis
from hil.transmissions import build_transmissions

BOOT_TIMEOUT = 3.0
ENABLE_TIMEOUT = 10.0
MISSED_TPDO_LIMIT = 5


@dataclass
class JointFeedback:
    """One cycle's measurements: joint space, plus what each drive reported of itself
    (``HardwareInterface.actuator_names`` order)."""

    positions: np.ndarray
    velocities: np.ndarray
    efforts: np.ndarray
    motor_torques: np.ndarray       # N·m on the motor shaft, as the drive reports it
    drive_states: tuple[str, ...]   # each drive's state in its own protocol's words


class HardwareInterface(ABC):
    """Joint-space access to a robot's actuated joints (``joint_names`` order)."""

    def __init__(self, robot: RobotDescription):
        self.robot = robot
        self.joint_names = tuple(j.name for j in robot.driven_joints)
        self.actuator_names = tuple(a.name for a in robot.actuators)

    @abstractmethod
    def start(self) -> JointFeedback:
        """Bring the hardware up until it follows position commands; return where it is."""

    @abstractmethod
    def cycle(self, positions: np.ndarray, velocities: np.ndarray) -> JointFeedback:
        """Send one cycle's commands; return the joint state measured in this cycle."""

    def faults(self) -> list[str]:
        """Faults found since the last call (each names the drive and joint)."""
        return []

    def reset_faults(self) -> None:
        """Clear latched faults and bring every actuator back to following commands; until
        :attr:`ready`, each holds where it is."""

    @property
    def ready(self) -> bool:
        """Whether every actuator follows commands (after start, or after a reset)."""
        return True

    def stop(self) -> None:
        """Leave every actuator disabled (brakes on where fitted)."""


class FakeHardwareInterface(HardwareInterface):
    """No CAN, no physics: the commanded state is the measured state."""

    def __init__(self, robot: RobotDescription):
        super().__init__(robot)
        n = len(self.joint_names)
        self._torques = np.zeros(len(self.actuator_names))
        self._states = ("FAKE",) * len(self.actuator_names)
        self._state = JointFeedback(np.zeros(n), np.zeros(n), np.zeros(n), self._torques,
                                    self._states)

    def start(self) -> JointFeedback:
        return self._state

    def cycle(self, positions, velocities) -> JointFeedback:
        feedback = self._state
        self._state = JointFeedback(np.array(positions, dtype=float),
                                    np.array(velocities, dtype=float), np.zeros(len(positions)),
                                    self._torques, self._states)
        return feedback


class CanHardwareInterface(HardwareInterface):
    """CAN master for every drive of a bus config."""

    def __init__(self, config: SystemConfig, buses: dict[str, can.BusABC],
                 reply_timeout: float | None = None):
        super().__init__(config.robot)
        self.config = config
        self.reply_timeout = reply_timeout if reply_timeout is not None else 0.8 * (
            1.0 / config.cycle_hz)
        self._networks: dict[str, canopen.Network] = {}
        self.axes: list[Cia402Axis] = []
        for bus in config.buses:
            network = canopen.Network(buses[bus.name])
            self._networks[bus.name] = network
            for drive in bus.drives:
                self.axes.append(Cia402Axis(drive, bus.name, on_feedback=self._on_feedback))
        self._by_actuator = {a.config.actuator: a for a in self.axes}
        self.actuator_names = tuple(a.config.actuator for a in self.axes)
        self.transmissions = build_transmissions(config.robot)
        index = {name: i for i, name in enumerate(self.joint_names)}
        self._joint_slices = [np.array([index[j] for j in t.joints]) for t in self.transmissions]
        self._cycle = 0
        self._stopping = False
        self._recovering = False
        self._reported: set[tuple[str, str, str]] = set()
        self._pending: list[str] = []
        self._arrived = threading.Condition()

    # --- bring-up ---------------------------------------------------------------------

    def start(self) -> JointFeedback:
        for network in self._networks.values():
            network.notifier = can.Notifier(network.bus, network.listeners, 0.1)
        for axis in self.axes:
            axis.attach(self._networks[axis.bus_name])
        for axis in self.axes:                         # reset: every drive boots afresh
            axis.node.nmt.send_command(0x81)
        deadline = time.monotonic() + BOOT_TIMEOUT
        for axis in self.axes:
            if not axis.booted.wait(max(0.0, deadline - time.monotonic())):
                raise HilError.single(
                    f"{axis.label} sent no boot-up message within {BOOT_TIMEOUT:g} s after "
                    "NMT reset", hint="is `hil sim` (or the real drive) running on this bus, "
                                      "with the same node id?")
        for axis in self.axes:
            axis.configure()
            axis.node.nmt.send_command(0x01)           # start: operational
        deadline = time.monotonic() + ENABLE_TIMEOUT
        hold = np.zeros(len(self.joint_names))
        while True:
            feedback = self.cycle(hold, np.zeros_like(hold), enabling=True)
            hold = feedback.positions
            waiting = [a for a in self.axes if a.state != "OPERATION ENABLED"]
            if not waiting:
                break
            faults = [a.fault_text() for a in waiting if a.fault_text()]
            if faults or time.monotonic() > deadline:
                raise HilError.single(
                    "drives did not reach OPERATION ENABLED: " + "; ".join(
                        faults or [f"{a.label} is {a.state}" for a in waiting]))
        self._pending.clear()
        return feedback

    # --- cyclic ------------------------------------------------------------------------------

    def cycle(self, positions, velocities, enabling: bool = False) -> JointFeedback:
        self._cycle += 1
        targets = self._actuator_targets(np.asarray(positions, dtype=float))
        for axis in self.axes:
            axis.begin_cycle(self._cycle)
            controlword = axis.next_controlword(self._stopping)
            # until an axis follows setpoints, its setpoint is where it is (no jump on enable)
            following = axis.state == "OPERATION ENABLED" and not (enabling or self._recovering)
            target = targets[axis.config.actuator] if following else axis.feedback.position
            self._networks[axis.bus_name].send_message(0x200 + axis.node_id,
                                                       axis.rpdo(controlword, target))
        for network in self._networks.values():
            network.send_message(SYNC_ID, b"")
        self._await_feedback()
        self._watch()
        if self._recovering and not self._stopping and all(
                a.state == "OPERATION ENABLED" for a in self.axes):
            self._recovering = False
        return self._joint_feedback()

    def _await_feedback(self) -> None:
        """Wait (up to the reply timeout) until every axis' TPDO of this cycle is in."""
        with self._arrived:
            self._arrived.wait_for(
                lambda: all(a.feedback.tpdo_cycle == self._cycle for a in self.axes),
                timeout=self.reply_timeout)

    def _on_feedback(self) -> None:
        with self._arrived:
            self._arrived.notify()

    def _actuator_targets(self, joint_positions: np.ndarray) -> dict[str, float]:
        targets = {}
        for transmission, joints in zip(self.transmissions, self._joint_slices):
            motor = transmission.joint_to_actuator_position(joint_positions[joints])
            targets.update(zip(transmission.actuators, motor))
        return targets

    def _joint_feedback(self) -> JointFeedback:
        n = len(self.joint_names)
        positions, velocities, efforts = np.zeros(n), np.zeros(n), np.zeros(n)
        for transmission, joints in zip(self.transmissions, self._joint_slices):
            axes = [self._by_actuator[a].feedback for a in transmission.actuators]
            positions[joints] = transmission.actuator_to_joint_position([f.position for f in axes])
            velocities[joints] = transmission.actuator_to_joint_velocity(
                [f.velocity for f in axes])
            efforts[joints] = transmission.actuator_to_joint_effort([f.torque for f in axes])
        return JointFeedback(positions, velocities, efforts,
                             np.array([a.feedback.torque for a in self.axes]),
                             tuple(a.state for a in self.axes))

    # --- faults -----------------------------------------------------------------------------

    def _watch(self) -> None:
        now = time.monotonic()
        for axis in self.axes:
            # (what, text): a silence is reported once per axis, not once per silent cycle
            problems = [("fault", axis.fault_text(self._stopping))]
            silence = now - axis.last_heartbeat
            if silence > 3 * axis.config.heartbeat_period:
                problems.append(("heartbeat", f"{axis.label} is silent: no heartbeat for "
                                              f"{silence * 1e3:.0f} ms"))
            if self._cycle - axis.feedback.tpdo_cycle > MISSED_TPDO_LIMIT:
                problems.append(("tpdo", f"{axis.label} is silent: no TPDO for "
                                         f"{self._cycle - axis.feedback.tpdo_cycle} cycles"))
            for what, problem in problems:
                key = (axis.label, what, problem if what == "fault" else "")
                if problem and key not in self._reported:
                    self._reported.add(key)
                    self._pending.append(problem)
                    self._stopping = True

    def faults(self) -> list[str]:
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
        self._stopping = False
        self._reported.clear()
        self._pending.clear()
        for axis in self.axes:
            axis.last_emcy = None

    @property
    def ready(self) -> bool:
        return not (self._stopping or self._recovering)

    def stop(self) -> None:
        """Disable every drive (shutdown, then disable voltage), then release the buses."""
        for controlword in (SHUTDOWN, DISABLE_VOLTAGE):
            for axis in self.axes:
                try:
                    self._networks[axis.bus_name].send_message(
                        0x200 + axis.node_id, axis.rpdo(controlword, axis.feedback.position))
                except can.CanError:
                    pass
            for network in self._networks.values():
                try:
                    network.send_message(SYNC_ID, b"")
                except can.CanError:
                    pass
            time.sleep(2.0 / self.config.cycle_hz)
        for network in self._networks.values():
            if network.notifier is not None:
                network.notifier.stop(1.0)
