"""A replay: a log's master frames fed to the simulated drives of a bus config, in one
process, and every drive's answers compared with the log's (:mod:`hil.replay.compare`).

Closed loop on the drives' side: each drive answers from its own state, which the frames
before made (SDO configuration, PDO mapping, NMT and 402 states, the trajectory so far), so
the answers of the n-th cycle are what this build's drives say to the same master. Two
clocks:

* ``cycles``, for a log of a lock-step run: the simulator in lock-step, its plant one
  control period per cycle, as the run's was: the same config gives the same answers bit
  for bit.
* ``log``, for a log of a real-time run (or of a real robot): the simulator in real time on
  the log's own timestamps (:meth:`hil.simulator.Simulator.follow`), its plant stepped up
  to each frame's time as the running simulator was (and every 10 ms between frames, as its
  watchdog thread wakes). The plant is first placed where the log's drives report their
  joints once the master cycles (that run's plant, or the robot, moved before the log
  began), and measured values are compared SETTLE cycles later (the drives' controllers
  settle on the log's state). Where in its step the run's plant was at a frame is not in
  the log: a position may be off by one plant step of the axis' motion beyond the
  tolerance.

Frames are fed in time order, each bus' in the log's order (:func:`hil.replay.log.frames`).
Drive frames logged before the log's first master frame are not compared (the drives'
boot-up, the heartbeats before the master came), nor the replay's answers to master frames
logged after the log's last frame from a drive of that bus (the log ended before they
could come).
Watchdogs and timed frames run on no clock in a replay: a drive's timed state (its
heartbeat) is sampled after each master frame that concerns it.
"""

from __future__ import annotations

import math
import time
import uuid
from collections.abc import Iterable, Sequence

import can
import numpy as np

from hil.bus_config import SystemConfig
from hil.can.delivery import FrameListener
from hil.can.frame import Frame
from hil.can.messages import frame_of
from hil.drives.profile import DriveProfile
from hil.protocols import Sender
from hil.replay.compare import (
    UNITS, AnswerStream, Answer, Divergence, JointStatistics, Tolerances, TimedStates,
    drive_units,
)
from hil.replay.log import BusFrames, LoggedFrame, Survey
from hil.replay.report import KEPT, Report
from hil.simulator import WATCHDOG_PERIOD, Simulator
from hil.realtime.timing import LOCK_STEP, REAL_TIME

#: the quantities a replay's plant is placed by (position, velocity of each actuator)
SEEDED = {"position": 0, "velocity": 1}
#: cycles after the plant is placed before measured values are compared
SETTLE = 10
#: how long (s of the log) a replay waits for every drive's first position
SEED_WAIT = 1.0
#: the statistics' quantities by name
QUANTITY_INDEX = {q: i for i, q in enumerate(JointStatistics.QUANTITIES)}
#: cycles summed up at a time (the statistics are numpy's work, a batch at a time)
BATCH = 512


class _Answers(FrameListener):
    """The replayed drives' frames of one bus, as they come (in the feeding thread)."""

    def __init__(self):
        self.frames: list[Frame] = []

    def on_frames(self, frames: Sequence[Frame]) -> None:
        self.frames.extend(frames)

    def on_message_received(self, msg: can.Message) -> None:
        self.frames.append(frame_of(msg))


class Replay:
    """Feeds a log's frames to a fresh simulator of ``config`` and compares its answers."""

    def __init__(self, config: SystemConfig, survey: Survey, clock: str,
                 tolerances: Tolerances, keep_values: bool = False):
        self.config = config
        self.survey = survey
        self.tolerances = tolerances
        self.keep_values = keep_values
        self.report = Report(clock)
        tag = uuid.uuid4().hex[:8]
        self._buses: list[can.BusABC] = []
        sim_buses, self._feeders, self._answers = {}, [], []
        for bus in config.buses:
            channel = f"hil-replay-{tag}-{bus.name}"
            sim_buses[bus.name] = can.Bus(interface="hil-virtual", channel=channel)
            feeder = can.Bus(interface="hil-virtual", channel=channel)
            answers = _Answers()
            feeder.deliver_to([answers])
            self._feeders.append(feeder)
            self._answers.append(answers)
            self._buses += [sim_buses[bus.name], feeder]
        self.sim = Simulator(config, sim_buses, LOCK_STEP if clock == "cycles" else REAL_TIME)
        self._tellers = [BusFrames(bus) for bus in config.buses]
        # (bus index, node id) -> (its config, its simulated drive)
        self._drives: dict[tuple[int, int], tuple] = {}
        for index, (bus, simulated) in enumerate(zip(config.buses, self.sim.buses)):
            for drive_config, drive in zip(bus.drives, simulated.drives):
                self._drives[index, drive_config.node_id] = (drive_config, drive)
        #: per bus: its (node id, simulated drive)
        self._on_bus = [[(node, drive) for (b, node), (_, drive) in self._drives.items()
                         if b == index] for index in range(len(config.buses))]
        actuators = tuple(self.sim.plant.actuator_names)
        self._actuator = {key: actuators.index(c.actuator) for key, (c, _) in self._drives.items()}
        self.report.statistics = JointStatistics(config, actuators, 1.0 / config.cycle_hz)
        #: (bus index, node id, identifier, extended) -> the drive's frames of that id
        self._streams: dict[tuple[int, int, int, bool], AnswerStream] = {}
        self._timed: dict[tuple[int, int, int], TimedStates] = {}
        #: cycle -> (logged, replayed) x quantity x actuator, motor side SI (NaN: none yet)
        self._rows: dict[int, list[float]] = {}
        self._width = len(actuators)
        self._now = 0.0                       # the log's time, for clock "log"
        #: the first logged positions and velocities per actuator (motor side, SI), until
        #: the plant is placed (on the log's clock)
        self._first = np.full((2, self._width), math.nan)
        self._first_report: float | None = None
        #: on the log's clock: the plant's step (s), by which a position may be off times
        #: its speed; each drive's last logged speed (counts/s)
        self._step_slack = self.sim.plant.timestep if clock == "log" else 0.0
        self._speed: dict[tuple[int, int], float] = {}
        #: the first cycle whose measured values are compared: a lock-step run's log began
        #: with its plant (nothing to place), else once the plant is placed
        self._measured_from = 0 if clock == "cycles" else math.inf
        self._next_tick = 0.0

    @property
    def _seeded(self) -> bool:
        """Whether the plant is where the log's was (placed, or a lock-step log's)."""
        return self._measured_from < math.inf

    # --- running ----------------------------------------------------------------------

    def run(self, frames: Iterable[LoggedFrame]) -> Report:
        """Replay every frame of the log (as :func:`hil.replay.log.frames` gives them)."""
        begun = time.perf_counter()
        self.sim.start()
        for answers in self._answers:
            answers.frames.clear()              # boot-ups before the master: not compared
        if self.report.clock == "log":
            self.sim.follow(lambda: self._now)
        try:
            for frame in frames:
                if frame.source.sender is Sender.MASTER:
                    self._feed(frame)
                elif frame.time >= self.survey.addressed_since(frame.bus,
                                                               frame.source.node_id):
                    self._logged(frame)
        finally:
            self.sim.close()
            for bus in self._buses:
                bus.shutdown()
        self._finish()
        self.report.wall_seconds = time.perf_counter() - begun
        self.report.survey_seconds = self.survey.seconds
        return self.report

    def _feed(self, frame: LoggedFrame) -> None:
        if not self._seeded and frame.source.cycle and self._ready_to_seed(frame.time):
            self._seed()
        if self.report.clock == "log":
            at = frame.time - (self.survey.first_time or 0.0)
            while self._next_tick < at:        # the running sim's watchdog thread's wake-ups
                self._now = self._next_tick
                self.sim.now()
                self._next_tick += WATCHDOG_PERIOD
            self._now = max(self._now, at)
            self.sim.now()
        plant_time = self.sim.plant.time
        cycle = round(plant_time * self.config.cycle_hz)
        self._feeders[frame.bus].send_frames((frame.frame,))
        for bus, answers in enumerate(self._answers):     # a lock-step cycle ends on one bus,
            for sent in answers.frames:                     # the drives answer on every bus
                self._replayed(bus, frame.time, sent, cycle, plant_time)
            answers.frames.clear()
        concerned = frame.source.node_id
        for node, drive in self._on_bus[frame.bus]:
            if concerned is None or concerned == node:
                self._sample(frame.bus, node, drive, cycle, plant_time)
        if len(self._rows) > BATCH + 2:     # the cycles before the last two are done
            self._flush(cycle - 2)

    def _first_state(self, bus: int, node: int, readings) -> None:
        """A logged drive's readings before the replay's plant is placed: the first position
        and velocity of its actuator kept."""
        actuator = self._actuator[bus, node]
        for reading in readings:
            q = SEEDED.get(reading.quantity)
            if q is not None and math.isnan(self._first[q, actuator]):
                self._first[q, actuator] = reading.value * reading.scale

    def _ready_to_seed(self, now: float) -> bool:
        """Every drive reported its position (a master starts its drives one by one), or
        SEED_WAIT passed since the first did (a drive that never reports one)."""
        reported = ~np.isnan(self._first[0])
        if not reported.any():
            return False
        if self._first_report is None:
            self._first_report = now
        return bool(reported.all()) or now - self._first_report > SEED_WAIT

    def _seed(self) -> None:
        """The replay's plant placed where the log's drives first reported their joints,
        moving as they reported (a real-time run's plant, or a robot, was running before the
        log began: joints fell or were moved). Measured values are compared SETTLE cycles
        later."""
        statistics = self.report.statistics
        positions = statistics.joint_values(0, self._first[0][:, None], absolute=True)[:, 0]
        velocities = statistics.joint_values(1, self._first[1][:, None], absolute=False)[:, 0]
        with self.sim.lock:
            self.sim.plant.set_joint_positions(
                {j: p for j, p in zip(statistics.joints, positions) if not math.isnan(p)},
                {j: v for j, v in zip(statistics.joints, velocities) if not math.isnan(v)})
        self.report.seeded = int(np.sum(~np.isnan(positions)))
        # the drives' answers to this cycle carry what they sampled before, and their
        # controllers' own state (integrals, filters) takes a few cycles to be the log's
        self._measured_from = round(self.sim.plant.time * self.config.cycle_hz) + SETTLE

    def _sample(self, bus: int, node: int, drive: DriveProfile, cycle: int, now: float) -> None:
        for can_id in drive.timed_ids():
            self._timed_states(bus, node, can_id).replay(drive.timed_content(can_id), cycle, now)

    def _replayed(self, bus: int, cause: float, sent: Frame, cycle: int, now: float
                  ) -> None:
        """A replayed drive's frame on ``bus``, in answer to a master frame logged at
        ``cause``."""
        source = self._tellers[bus].source(sent)
        if source is None or source.sender is not Sender.DRIVE:
            return
        _, drive = self._drives[bus, source.node_id]
        if drive.timed(sent):
            return           # a heartbeat on the wall clock (canopen's own timer thread)
        stream = self._stream(bus, source.node_id, sent, source.what)
        last = self.survey.last_drive_time[bus]
        if last is None or cause > last:
            self.report.after_the_log += 1
            return
        stream.replayed.append(Answer(sent, cycle, now))
        self._compare(bus, source.node_id, stream)

    def _logged(self, logged: LoggedFrame) -> None:
        key = (logged.bus, logged.source.node_id)
        _, drive = self._drives[key]
        frame = logged.frame
        if drive.timed(frame):
            if frame.identifier in drive.timed_ids():
                self._timed_states(logged.bus, logged.source.node_id, frame.identifier).log(
                    frame.data, logged.number)
            return
        stream = self._stream(logged.bus, logged.source.node_id, frame, logged.source.what)
        stream.logged.append(Answer(frame, 0, 0.0, logged.number))
        self._compare(logged.bus, logged.source.node_id, stream)

    def _stream(self, bus: int, node: int, frame: Frame, what: str) -> AnswerStream:
        key = (bus, node, frame.identifier, frame.extended)
        stream = self._streams.get(key)
        if stream is None:
            drive_config, _ = self._drives[bus, node]
            stream = self._streams[key] = AnswerStream(self.config.buses[bus].name,
                                                       drive_config, frame.identifier, what)
        return stream

    def _timed_states(self, bus: int, node: int, can_id: int) -> TimedStates:
        key = (bus, node, can_id)
        states = self._timed.get(key)
        if states is None:
            drive_config, _ = self._drives[bus, node]
            states = self._timed[key] = TimedStates(self.config.buses[bus].name, drive_config,
                                                    f"heartbeat 0x{can_id:03X}")
        return states

    # --- comparing --------------------------------------------------------------------

    def _compare(self, bus: int, node: int, stream: AnswerStream) -> None:
        drive_config, drive = self._drives[bus, node]
        for logged, replayed in stream.pairs():
            self.report.compared += 1
            same = logged.frame.data == replayed.frame.data
            expected = drive.readings(logged.frame)
            got = expected if same else drive.readings(replayed.frame)
            if not self._seeded and expected:
                self._first_state(bus, node, expected)
            if self._step_slack and expected:
                for reading in expected:
                    if reading.quantity == "velocity":
                        self._speed[bus, node] = abs(drive_units(drive_config, reading))
            if (replayed.cycle >= self._measured_from and expected is not None
                    and got is not None and len(expected) == len(got)):
                self._row(bus, node, replayed.cycle, expected, got)
            if same:
                continue
            if expected is None or got is None or len(expected) != len(got):
                self._diverged(stream.divergence(logged, replayed, "bytes",
                                                 logged.frame.data.hex(" "),
                                                 replayed.frame.data.hex(" ")))
                continue
            for a, b in zip(expected, got):
                self._check(bus, stream, logged, replayed, drive_config, a, b)

    def _check(self, bus, stream, logged, replayed, drive_config, a, b) -> None:
        if a.value == b.value:
            return
        if replayed.cycle < self._measured_from and a.quantity in UNITS:
            self.report.before_seed += 1   # the plant's state before the log: no one's
            return
        if a.quantity is None or (a.quantity == "derived" and self.tolerances.exact):
            self._diverged(stream.divergence(logged, replayed, a.name, f"{a.value:g}",
                                             f"{b.value:g}"))
        elif a.quantity == "derived":
            self.report.derived_unchecked += 1
        else:
            difference = abs(drive_units(drive_config, b) - drive_units(drive_config, a))
            tolerance = self.tolerances.of(drive_config, a.quantity)
            if a.quantity == "position" and self._step_slack:
                # where in its step the run's plant was is not in the log: a plant step of
                # the axis' motion (at its last logged speed) more
                tolerance += self._speed.get((bus, drive_config.node_id), 0.0) * self._step_slack
            if difference > tolerance:
                unit = UNITS[a.quantity]
                self._diverged(stream.divergence(
                    logged, replayed, a.name, f"{a.value:g}",
                    f"{b.value:g} ({difference:.3g} {unit} off, tolerance {tolerance:g})",
                    difference))

    def _diverged(self, divergence: Divergence) -> None:
        report = self.report
        report.divergence_count += 1
        report.by_drive[divergence.drive] = report.by_drive.get(divergence.drive, 0) + 1
        first = report.first
        if len(report.divergences) < KEPT or (first is not None
                                              and divergence.cycle <= first.cycle):
            report.divergences.append(divergence)

    def _row(self, bus: int, node: int, cycle: int, expected, got) -> None:
        """A cycle's first reading of each quantity of a drive, logged and replayed (a flat
        list per cycle: side x quantity x actuator, filled as frames come)."""
        width = self._width
        row = self._rows.get(cycle)
        if row is None:
            row = self._rows[cycle] = [math.nan] * (6 * width)
        actuator = self._actuator[bus, node]
        for side, readings in ((0, expected), (1, got)):
            for reading in readings:
                q = QUANTITY_INDEX.get(reading.quantity)
                if q is not None:
                    k = (3 * side + q) * width + actuator
                    if row[k] != row[k]:                     # NaN: none yet this cycle
                        row[k] = reading.value * reading.scale

    def _flush(self, before: int | None) -> None:
        """Sum up the cycles before ``before`` (all: None), once BATCH of them are done."""
        done = sorted(c for c in self._rows if before is None or c < before)
        if not done or (before is not None and len(done) < BATCH):
            return
        rows = np.array([self._rows.pop(c) for c in done]).reshape(len(done), 2, 3,
                                                                   self._width)
        cycles = np.array(done)
        statistics = self.report.statistics
        statistics.add(cycles, rows[:, 1] - rows[:, 0])
        if self.keep_values:
            position, torque = (JointStatistics.QUANTITIES.index(q) for q in ("position", "torque"))
            self.report.values.append((cycles, *(
                statistics.joint_values(q, rows[:, side, q].T, absolute=True)
                for q in (position, torque) for side in (0, 1))))

    def _finish(self) -> None:
        self._flush(None)
        self.report.plant_seconds = self.sim.plant.time
        self.report.cycles = round(self.sim.plant.time * self.config.cycle_hz)
        for stream in self._streams.values():
            leftover = stream.leftover()
            if leftover is not None:
                self._diverged(leftover)
        for states in self._timed.values():
            divergence = states.divergence()
            if divergence is None:
                self.report.states_checked += len(states.logged)
            else:
                self._diverged(divergence)
