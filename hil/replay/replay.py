"""A replay: a log's master frames fed to the simulated drives of a bus config, in one
process, on one of two clocks, and every drive's answers compared with the log's.

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
  joints once the master cycles (:mod:`hil.replay.seed`).

Frames are fed in time order, each bus' in the log's order (:func:`hil.replay.log.frames`).
The parts: :mod:`.rig` (the simulator, a feeder and an answer collector per bus),
:mod:`.streams` (the answers, logged and replayed, paired), :mod:`.judge` (each pair
compared), :mod:`.rows` (the compared values' statistics).
"""

from __future__ import annotations

import time
from collections.abc import Iterable

from hil.bus_config import SystemConfig
from hil.protocols import Sender
from hil.replay.compare import JointStatistics, Tolerances
from hil.replay.judge import Judge
from hil.replay.log import LoggedFrame, Survey
from hil.replay.report import Report
from hil.replay.rig import Rig
from hil.replay.rows import BATCH, CycleRows
from hil.replay.seed import PlantSeed
from hil.replay.streams import Streams
from hil.simulator import WATCHDOG_PERIOD


class Replay:
    """Feeds a log's frames to a fresh simulator of ``config`` and compares its answers."""

    def __init__(self, config: SystemConfig, survey: Survey, clock: str,
                 tolerances: Tolerances, keep_values: bool = False):
        self.config = config
        self.survey = survey
        self.tolerances = tolerances
        self.keep_values = keep_values
        self.report = Report(clock)
        self._rig = rig = Rig(config, clock)
        self.sim = rig.sim
        width = len(rig.actuators)
        self.report.statistics = JointStatistics(config, rig.actuators, 1.0 / config.cycle_hz)
        self._seed = PlantSeed(clock, width)
        self._rows = CycleRows(self.report, width, keep_values)
        self._judge = Judge(rig.drives, rig.actuator, tolerances, self.report, self._seed,
                            self._rows, self.sim.plant.timestep if clock == "log" else 0.0)
        self._streams = Streams(config, survey, rig.drives, self._judge, self.report)
        self._now = 0.0                       # the log's time, for clock "log"
        self._next_tick = 0.0

    def run(self, frames: Iterable[LoggedFrame]) -> Report:
        """Replay every frame of the log (as :func:`hil.replay.log.frames` gives them)."""
        begun = time.perf_counter()
        self._rig.start()
        if self.report.clock == "log":
            self.sim.follow(lambda: self._now)
        try:
            for frame in frames:
                if frame.source is None:
                    self._streams.logged_sensor(frame)
                elif frame.source.sender is Sender.MASTER:
                    self._feed(frame)
                elif frame.time >= self.survey.addressed_since(frame.bus,
                                                               frame.source.node_id):
                    self._streams.logged(frame)
        finally:
            self._rig.close()
        self._finish()
        self.report.wall_seconds = time.perf_counter() - begun
        self.report.survey_seconds = self.survey.seconds
        return self.report

    def _feed(self, frame: LoggedFrame) -> None:
        seed = self._seed
        if not seed.placed and frame.source.cycle and seed.ready(frame.time):
            self.report.seeded = seed.place(self.sim, self.report.statistics,
                                            self.config.cycle_hz)
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
        rig, streams = self._rig, self._streams
        rig.feeders[frame.bus].send_frames((frame.frame,))
        for bus, answers in enumerate(rig.answers):     # a lock-step cycle ends on one bus,
            for sent in answers.frames:                  # the drives answer on every bus
                streams.replayed(bus, frame.time, sent, cycle, plant_time)
            answers.frames.clear()
        concerned = frame.source.node_id
        for node, drive in rig.on_bus[frame.bus]:
            if concerned is None or concerned == node:
                streams.sample(frame.bus, node, drive, cycle, plant_time)
        if len(self._rows.rows) > BATCH + 2:  # the cycles before the last two are done
            self._rows.flush(cycle - 2)

    def _finish(self) -> None:
        self._rows.flush(None)
        self.report.plant_seconds = self.sim.plant.time
        self.report.cycles = round(self.sim.plant.time * self.config.cycle_hz)
        self._streams.finish()
