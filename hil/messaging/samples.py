"""Every control cycle, recorded: what the controller commanded and what it measured.

The controller fills a :class:`ControlSampleBuffer` each cycle (preallocated
arrays, no allocation per cycle) and publishes a :class:`ControlSamples`
batch a few dozen times a second as ``hil_msgs/ControlSamples``. Batches
carry the number of their first cycle, so a receiver can tell a lost batch
from a quiet controller.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from hil.hardware import JointFeedback
from hil.messaging import cdr


@dataclass(frozen=True)
class ControlSamples:
    """A batch of consecutive control cycles; 2-D arrays are (cycles, joints|actuators)."""

    first_cycle: int
    period: float
    wall_time: np.ndarray            # s since the epoch
    control_time: np.ndarray         # s on the controller's clock
    joint_names: tuple[str, ...]
    reference: np.ndarray            # the trajectory controller's desired position
    reference_velocity: np.ndarray
    position: np.ndarray             # measured, joint side
    velocity: np.ndarray
    effort: np.ndarray
    actuator_names: tuple[str, ...]
    motor_torque: np.ndarray         # N·m on the motor shaft, as the drive reports it
    drive_state: np.ndarray          # uint8 index into state_names
    state_names: tuple[str, ...]
    #: s, the control loop's own timing per cycle (NaN where not measured: lock-step, fake
    #: hardware, an answer that did not come): release to release, and SYNC out to the last
    #: answer in
    cycle_period: np.ndarray
    round_trip: np.ndarray

    def __len__(self) -> int:
        return len(self.wall_time)

    @classmethod
    def empty(cls) -> ControlSamples:
        """A batch of no cycles (encoding one builds the codec ahead of time)."""
        none, table = np.zeros(0), np.zeros((0, 0))
        return cls(0, 0.0, none, none, (), table, table, table, table, table, (), table,
                   np.zeros((0, 0), dtype=np.uint8), (), none, none)

    @property
    def next_cycle(self) -> int:
        return self.first_cycle + len(self)

    def encode(self) -> bytes:
        return cdr.encode(cdr.msg(
            cdr.CONTROL_SAMPLES, first_cycle=self.first_cycle, period=self.period,
            wall_time=self.wall_time, control_time=self.control_time,
            joint_names=list(self.joint_names), reference=self.reference.ravel(),
            reference_velocity=self.reference_velocity.ravel(), position=self.position.ravel(),
            velocity=self.velocity.ravel(), effort=self.effort.ravel(),
            actuator_names=list(self.actuator_names), motor_torque=self.motor_torque.ravel(),
            drive_state=self.drive_state.ravel(), state_names=list(self.state_names),
            cycle_period=self.cycle_period, round_trip=self.round_trip))

    @classmethod
    def decode(cls, data: bytes) -> ControlSamples:
        """Raise ValueError naming what is wrong with a malformed payload."""
        message = cdr.decode(data, cdr.CONTROL_SAMPLES)
        cycles = len(message.wall_time)
        joints, actuators = len(message.joint_names), len(message.actuator_names)

        def table(name: str, width: int) -> np.ndarray:
            values = np.asarray(getattr(message, name))
            if len(values) != cycles * width:
                raise ValueError(f"malformed {cdr.CONTROL_SAMPLES}: '{name}' has {len(values)} "
                                 f"values, {cycles} cycles x {width} expected")
            return values.reshape(cycles, width)

        for name in ("control_time", "cycle_period", "round_trip"):
            if len(getattr(message, name)) != cycles:
                raise ValueError(f"malformed {cdr.CONTROL_SAMPLES}: {len(getattr(message, name))}"
                                 f" values of '{name}' for {cycles} wall times")
        states = table("drive_state", actuators)
        if states.size and states.max() >= len(message.state_names):
            raise ValueError(f"malformed {cdr.CONTROL_SAMPLES}: drive state {states.max()} "
                             f"but only {len(message.state_names)} state names")
        return cls(message.first_cycle, message.period, np.asarray(message.wall_time),
                   np.asarray(message.control_time), tuple(message.joint_names),
                   table("reference", joints), table("reference_velocity", joints),
                   table("position", joints), table("velocity", joints),
                   table("effort", joints), tuple(message.actuator_names),
                   table("motor_torque", actuators), states, tuple(message.state_names),
                   np.asarray(message.cycle_period), np.asarray(message.round_trip))


#: ControlSampleBuffer keeps the codes of this many combinations of drive states at most
STATE_ROWS = 64


class ControlSampleBuffer:
    """Collects one row per control cycle; :meth:`take` empties it into a batch."""

    def __init__(self, joint_names, actuator_names, period: float, capacity: int):
        self.joint_names, self.actuator_names = tuple(joint_names), tuple(actuator_names)
        self.period, self.capacity = period, capacity
        joints, actuators = len(self.joint_names), len(self.actuator_names)
        self._wall, self._time = np.zeros(capacity), np.zeros(capacity)
        self._period, self._round_trip = np.zeros(capacity), np.zeros(capacity)
        self._joint_tables = [np.zeros((capacity, joints)) for _ in range(5)]
        self._torque = np.zeros((capacity, actuators))
        self._state = np.zeros((capacity, actuators), dtype=np.uint8)
        self._state_index: dict[str, int] = {}
        #: the row of state codes of each tuple of drive states seen (a few: the states the
        #: drives pass through together), at most STATE_ROWS of them
        self._state_rows: dict[tuple[str, ...], np.ndarray] = {}
        self._rows = 0
        self._first_cycle = 0

    @property
    def full(self) -> bool:
        return self._rows == self.capacity

    def add(self, cycle: int, control_time: float, reference: np.ndarray,
            reference_velocity: np.ndarray, feedback: JointFeedback,
            period: float = np.nan, round_trip: float = np.nan) -> None:
        """Record cycle ``cycle`` (consecutive cycles make one batch), with the loop's period
        and round trip where measured. Ignored when full."""
        row = self._rows
        if row == self.capacity:
            return
        if row == 0:
            self._first_cycle = cycle
        self._wall[row], self._time[row] = time.time(), control_time
        self._period[row], self._round_trip[row] = period, round_trip
        for table, values in zip(self._joint_tables, (reference, reference_velocity,
                                                      feedback.positions, feedback.velocities,
                                                      feedback.efforts)):
            table[row] = values
        self._torque[row] = feedback.motor_torques
        codes = self._state_rows.get(feedback.drive_states)
        if codes is None:
            codes = self._state_codes(feedback.drive_states)
        self._state[row] = codes
        self._rows = row + 1

    def _state_codes(self, states: tuple[str, ...]) -> np.ndarray:
        index = self._state_index
        codes = np.array([index.setdefault(state, len(index)) for state in states],
                         dtype=np.uint8)
        if len(self._state_rows) == STATE_ROWS:
            self._state_rows.clear()
        self._state_rows[states] = codes
        return codes

    def take(self) -> ControlSamples | None:
        """The rows recorded since the last call (None if there are none)."""
        rows = self._rows
        if rows == 0:
            return None
        self._rows = 0
        reference, reference_velocity, position, velocity, effort = (
            table[:rows].copy() for table in self._joint_tables)
        return ControlSamples(
            self._first_cycle, self.period, self._wall[:rows].copy(), self._time[:rows].copy(),
            self.joint_names, reference, reference_velocity, position, velocity, effort,
            self.actuator_names, self._torque[:rows].copy(), self._state[:rows].copy(),
            tuple(self._state_index), self._period[:rows].copy(), self._round_trip[:rows].copy())
