"""What a replay compares, and how it reports a difference.

A drive's answers (every frame it sends in answer to its master) are compared one for one,
in order, per drive and id: the n-th TPDO1 of node 2 in the log against the n-th the
replayed node 2 sent. Byte for byte where the frame is state (SDO answers and aborts, EMCY
codes, boot-ups, statuswords); measured values (positions, velocities, torques:
:class:`hil.drives.profile.Reading`) within :class:`Tolerances`, exact by default. What a
drive sends on its own clock (a heartbeat) is compared as the sequence of states it
reports (:class:`TimedStates`): a heartbeat is sampled at wall-clock times, so the log
holds each state the drive was in for long enough, in order, and the replayed drive must
have gone through them all.

Units of tolerances and differences are the drive's own, the same for every protocol:
positions in encoder counts (the bus config's ``encoder_counts_per_rev``), velocities in
counts/s, torques in per mille of the rated torque. :class:`JointStatistics` gives the
differences per joint in joint units (rad, m, N·m) through the robot's transmissions.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from hil.bus_config import DriveConfig, SystemConfig
from hil.can.frame import Frame
from hil.drives.profile import Reading
from hil.errors import UsageError
from hil.transmissions import build_transmissions

#: the measured quantities a tolerance can be set for, with their unit in messages
UNITS = {"position": "counts", "velocity": "counts/s", "torque": "per mille"}
#: of the differences kept for the report, per joint, the largest seconds shown
WORST_SECONDS = 3


@dataclass(frozen=True)
class Tolerances:
    """Allowed differences per quantity (drive units, see the module), and per joint."""

    default: dict[str, float] = field(default_factory=dict)
    #: joint name -> quantity -> tolerance
    joints: dict[str, dict[str, float]] = field(default_factory=dict)

    @classmethod
    def parse(cls, texts: list[str], base: dict[str, float], config: SystemConfig
              ) -> Tolerances:
        """``[JOINT:]QUANTITY=VALUE`` items over ``base`` (UsageError naming a bad one)."""
        joints = {j for d in config.drives for j in d.joints}
        default, per_joint = dict(base), {}
        for text in texts:
            target, sep, value = text.partition("=")
            joint, _, quantity = target.rpartition(":")
            try:
                number = float(value)
            except ValueError:
                number = -1.0
            if not sep or quantity not in UNITS or not number >= 0 or (joint and joint not in
                                                                        joints):
                raise UsageError.single(
                    f"--tolerance {text}: give [JOINT:]QUANTITY=VALUE, QUANTITY one of "
                    f"{', '.join(f'{q} ({u})' for q, u in UNITS.items())}, VALUE >= 0"
                    + (f", JOINT one of {', '.join(sorted(joints))}" if joint else ""))
            (per_joint.setdefault(joint, {}) if joint else default)[quantity] = number
        return cls(default, per_joint)

    @property
    def exact(self) -> bool:
        """Every tolerance 0: bit for bit."""
        return not any(self.default.values()) and not any(
            value for per_joint in self.joints.values() for value in per_joint.values())

    def of(self, drive: DriveConfig, quantity: str) -> float:
        """A drive's tolerance: the loosest its joints are given, else the default (0)."""
        given = [self.joints[j][quantity] for j in drive.joints
                 if quantity in self.joints.get(j, {})]
        return max(given) if given else self.default.get(quantity, 0.0)


def drive_units(drive: DriveConfig, reading: Reading) -> float:
    """A reading in the drive's units (counts, counts/s, per mille of rated torque)."""
    si = reading.value * reading.scale
    if reading.quantity in ("position", "velocity"):
        return si * drive.encoder_counts_per_rev / (2 * math.pi)
    if reading.quantity == "torque":
        return si / drive.rated_torque * 1000
    return si


@dataclass(frozen=True)
class Divergence:
    """One difference between the log and the replay."""

    cycle: int
    time: float              # plant time of the replay (s)
    bus: str
    drive: str               # the drive's label: node 2 (joint2)
    frame: str               # "TPDO1 0x182"
    field: str               # the object or value ("0x6064"), "bytes", "state", "count"
    expected: str            # what the log has
    got: str                 # what the replay has
    log_frame: int | None    # its frame number in the log
    size: float = math.inf   # the difference in drive units (inf: state, bytes, counts)

    def __str__(self) -> str:
        where = f" (frame {self.log_frame} of the log)" if self.log_frame else ""
        return (f"cycle {self.cycle} ({self.time:.3f} s), bus '{self.bus}', {self.drive}, "
                f"{self.frame} {self.field}: the log has {self.expected}, the replay "
                f"{self.got}{where}")


@dataclass
class Answer:
    """A frame of a drive's, waiting for its counterpart on the other side."""

    frame: Frame
    cycle: int
    time: float
    log_frame: int | None = None


class AnswerStream:
    """One device's frames of one id (a drive's, a sensor's), the log's against the
    replay's, in order."""

    def __init__(self, bus: str, device: str, identifier: int, what: str):
        """``device``: whose frames, in words (a drive's label, "sensor 'imu'")."""
        self.bus, self.device = bus, device
        self.frame = f"{what} 0x{identifier:03X}"
        self.logged: deque[Answer] = deque()
        self.replayed: deque[Answer] = deque()
        self.compared = 0

    def pairs(self):
        """Each (logged, replayed) pair that both sides have now."""
        while self.logged and self.replayed:
            self.compared += 1
            yield self.logged.popleft(), self.replayed.popleft()

    def divergence(self, logged: Answer, replayed: Answer, field: str, expected: str, got: str,
                   size: float = math.inf) -> Divergence:
        return Divergence(replayed.cycle, replayed.time, self.bus, self.device, self.frame,
                          field, expected, got, logged.log_frame, size)

    def leftover(self) -> Divergence | None:
        """At the end: the first frame one side has and the other lacks."""
        if self.logged:
            first = self.logged[0]
            return Divergence(first.cycle, first.time, self.bus, self.device, self.frame,
                              "count", f"{len(self.logged)} more", "none", first.log_frame)
        if self.replayed:
            first = self.replayed[0]
            return Divergence(first.cycle, first.time, self.bus, self.device, self.frame,
                              "count", "none" if not self.compared else "no more",
                              f"{len(self.replayed)} more: the log lacks this drive's "
                              "answers from here", None)
        return None


class TimedStates:
    """One drive's timed frames of one id (its heartbeat): the distinct states the log
    reports, which must come up in order in the states the replayed drive went through."""

    def __init__(self, bus: str, drive: DriveConfig, frame: str):
        self.bus, self.drive, self.frame = bus, drive, frame
        self.replayed: list[tuple[bytes, int, float]] = []     # (state, cycle, time)
        self.logged: list[tuple[bytes, int | None]] = []        # (state, log frame)

    def replay(self, state: bytes | None, cycle: int, time: float) -> None:
        if state is not None and (not self.replayed or self.replayed[-1][0] != state):
            self.replayed.append((state, cycle, time))

    def log(self, data: bytes, log_frame: int) -> None:
        if not self.logged or self.logged[-1][0] != data:
            self.logged.append((data, log_frame))

    def divergence(self) -> Divergence | None:
        """The first logged state the replayed drive never reached in order, if any."""
        position = 0
        for state, log_frame in self.logged:
            while position < len(self.replayed) and self.replayed[position][0] != state:
                position += 1
            if position == len(self.replayed):
                last = self.replayed[-1] if self.replayed else (b"", 0, 0.0)
                return Divergence(last[1], last[2], self.bus, self.drive.label, self.frame,
                                  "state", state.hex(" "), "never after " + (
                                      self.replayed[-1][0].hex(" ") if self.replayed
                                      else "nothing"), log_frame)
        return None


class JointStatistics:
    """The differences of each cycle, per joint in joint units, summed up: rms and max,
    the cycle of the max, and the seconds where they were largest."""

    QUANTITIES = ("position", "velocity", "torque")

    def __init__(self, config: SystemConfig, actuators: tuple[str, ...], cycle: float):
        self._parts = [(part, [actuators.index(a) for a in part.actuators])
                       for part in build_transmissions(config.robot)]
        self.joints = tuple(j for part, _ in self._parts for j in part.joints)
        self._cycle = cycle
        shape = (len(self.QUANTITIES), len(self.joints))
        self.count = np.zeros(shape)
        self.square = np.zeros(shape)
        self.largest = np.zeros(shape)
        self.largest_cycle = np.zeros(shape, dtype=int)
        #: second -> (quantities x joints squared sums, counts)
        self.seconds: dict[int, tuple[np.ndarray, np.ndarray]] = {}

    def joint_values(self, quantity: int, motor: np.ndarray, absolute: bool) -> np.ndarray:
        """Motor-side values (SI, actuators x cycles, NaN where missing) in joint units
        (joints x cycles), transmission by transmission; with ``absolute`` positions get the
        joints' offsets."""
        result = np.full((len(self.joints),) + motor.shape[1:], math.nan)
        column = 0
        for part, rows in self._parts:
            values = motor[rows]
            if self.QUANTITIES[quantity] == "torque":
                mapped = part.actuator_to_joint_effort(values)
            else:
                mapped = part.actuator_to_joint_velocity(values)
                if absolute and self.QUANTITIES[quantity] == "position":
                    mapped = (mapped.T + part.joint_offsets).T
            result[column:column + len(part.joints)] = mapped
            column += len(part.joints)
        return result

    def add(self, cycles: np.ndarray, differences: np.ndarray) -> None:
        """Cycles' motor-side differences (cycles x quantities x actuators, SI, NaN: none)."""
        seconds, where = np.unique((cycles * self._cycle).astype(int), return_inverse=True)
        squares = np.zeros((len(seconds), len(self.QUANTITIES), len(self.joints)))
        counts = np.zeros_like(squares)
        for q in range(len(self.QUANTITIES)):
            joint = np.abs(self.joint_values(q, differences[:, q, :].T, absolute=False)).T
            seen = ~np.isnan(joint)
            values = np.where(seen, joint, 0.0)
            self.count[q] += seen.sum(axis=0)
            self.square[q] += (values ** 2).sum(axis=0)
            at = values.argmax(axis=0)
            best = values[at, np.arange(len(self.joints))]
            larger = best > self.largest[q]
            self.largest[q] = np.where(larger, best, self.largest[q])
            self.largest_cycle[q] = np.where(larger, cycles[at], self.largest_cycle[q])
            np.add.at(squares[:, q], where, values ** 2)
            np.add.at(counts[:, q], where, seen)
        for k, second in enumerate(seconds.tolist()):
            old = self.seconds.get(second)
            self.seconds[second] = ((squares[k], counts[k]) if old is None
                                    else (old[0] + squares[k], old[1] + counts[k]))

    def rms(self) -> np.ndarray:
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.sqrt(self.square / self.count)

    def worst_seconds(self, quantity: int, joint: int) -> list[tuple[int, float]]:
        """The seconds of the run with the largest rms difference of a joint, largest
        first: where a difference grows."""
        found = [(second, math.sqrt(sums[0][quantity, joint] / sums[1][quantity, joint]))
                 for second, sums in self.seconds.items() if sums[1][quantity, joint]]
        return sorted(found, key=lambda item: -item[1])[:WORST_SECONDS]
