"""The simulated bench: the MuJoCo plant and every drive of a bus config.

Two time modes:

* real-time: plant time follows the wall clock. Whatever touches the plant
  or a drive (a frame arriving, a status read, the periodic watchdog check)
  enters :class:`PlantPresent`, which first steps the plant, with the drives'
  inner loops, up to the present; so a frame acts on and samples the state
  at its arrival, and no thread has to wake at the plant's rate (in one
  process such a thread fought the controller's for the GIL). Drives answer
  each cycle's command (SYNC, or a command frame) at once, as the lock is
  left (a bus' answers to one delivery in one send), and send their timed
  messages when due;
* lock-step: the plant advances exactly one control period once every drive
  has had its command of the cycle, so a run is reproducible bit for bit and
  may go faster than real time. The replies leave only after the step, so
  the controller cannot start the next cycle early.

Threads: each bus' frame router (:mod:`hil.can.router`) is called back by
python-can's Notifier (or by the sender's thread, on ``hil-virtual``); one
re-entrant lock guards the plant and all drives (in real time inside
PlantPresent; in lock-step a plain one). The watchdogs run on the wall
clock in both modes; in lock-step they are stretched to at least
LOCK_STEP_WATCHDOG, since nothing moves between commands there: a late
controller is no hazard, and the watchdog only has to find a dead one.

:class:`Simulator` composes the jobs, each in its module: building the plant and the drives
from the config (:mod:`.build`), stepping the plant in time (:mod:`.stepping`), the cycles
(:mod:`.cycles`) and fault injection (:mod:`.faults`).
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from contextlib import AbstractContextManager

import can

from hil.bus_config import DriveConfig, SystemConfig
from hil.can import batches, deliver_under, held_together
from hil.can.faults import DriveFaultKind
from hil.can.router import start_router
from hil.drives import DriveProfile
from hil.realtime.present import PlantPresent
from hil.realtime.stalls import Stall, StallDetector
from hil.realtime.timing import REAL_TIME, Timing
from hil.simulator.build import (LOCK_STEP_WATCHDOG, SimulatedBus, bench_plant,
                                 attach_sensors, close_sensors, drive_parameters,
                                 simulated_buses, simulated_force_torques,
                                 simulated_sensors)
from hil.sensors.force_torque import SimulatedForceTorque
from hil.sensors.imu import SimulatedImu
from hil.simulator.cycles import CycleBook
from hil.simulator.faults import FaultInjection
from hil.simulator.stepping import MAX_CATCH_UP, PlantStepping, RealTimeClock

__all__ = ["LOCK_STEP_WATCHDOG", "MAX_CATCH_UP", "WATCHDOG_PERIOD", "SimulatedBus", "Simulator",
           "bench_plant", "drive_parameters"]

WATCHDOG_PERIOD = 0.01


class Simulator:
    """Plant + drives + buses. Start with :meth:`start`, end with :meth:`close`."""

    def __init__(self, config: SystemConfig, buses: dict[str, can.BusABC],
                 timing: Timing = REAL_TIME):
        self.config = config
        self.timing = timing
        self.lock_step = timing.lock_step
        self.plant = bench_plant(config)
        self._stepping = PlantStepping(self.plant)
        self.sensors = self._stepping.sensors = simulated_sensors(config, self.plant)
        self.force_torques = simulated_force_torques(config, self.plant)
        self._real_time = RealTimeClock(self._stepping)
        # lock-step: nothing moves the plant between commands, nothing to advance on entry
        # (a plain lock, cheaper a cycle: docs/performance.md, "2026-11-28, fourth step: a bus'
        # cycle in one send (issue 48)")
        present = None if timing.lock_step else PlantPresent(self._real_time.advance)
        self.lock: AbstractContextManager = threading.RLock() if present is None else present
        self.buses: list[SimulatedBus] = simulated_buses(config, buses, timing, self.lock,
                                                         self._stepping)
        self.drives = self._stepping.drives
        self._cycles = CycleBook(self.buses, self.drives, self._stepping.step,
                                 config.steps_per_cycle)
        if present is not None:        # real time: a delivery's replies sent as it leaves
            present.leave = self._cycles.send_taken
        # chosen once here: the command path is hot (a call a drive a cycle)
        on_command = (self._cycles.commanded_in_lock_step if timing.lock_step
                      else self._cycles.commanded)
        for drive in self.drives:
            drive.on_command = on_command
        self._faults = FaultInjection(config, self.buses, self.lock, self._cycles)
        #: the blocks that hold the buses' frames for one message (a watchdog check's)
        self._batches = batches(buses.values())
        #: real time: the process' own stalls, found from the watchdog's wake-ups
        self.stalls = StallDetector("sim", WATCHDOG_PERIOD)
        #: called with each stall found (in the thread that runs :meth:`run`)
        self.on_stall: Callable[[Stall], None] | None = None
        self._stop = threading.Event()
        self._stepping.measure()

    @property
    def cycles(self) -> int:
        """Cycles run: lock-step, the plant's; real time, the most cycle frames (SYNCs,
        commands) any drive has had from its master, whoever the master is."""
        return self._cycles.cycles

    @property
    def overruns(self) -> int:
        """Real time: gaps skipped (the process stalled)."""
        return self._real_time.overruns

    @property
    def wall_clock(self) -> Callable[[], float]:
        """What plant time follows in real time (s)."""
        return self._real_time.wall_clock

    @wall_clock.setter
    def wall_clock(self, clock: Callable[[], float]) -> None:
        self._real_time.wall_clock = clock

    @property
    def _clock(self) -> tuple[float, int] | None:
        """Real time, while run() runs: (the clock's epoch, plant steps done since)."""
        return self._real_time.started

    # --- life cycle -------------------------------------------------------------

    def start(self) -> None:
        """Connect every drive to its bus: boot-up messages, heartbeats, cycle frames."""
        # a message of frames (a cycle's, over Zenoh) in one entry of the plant's lock
        deliver_under((simulated.bus for simulated in self.buses), self.lock)
        for simulated in self.buses:
            # the drives' side: a frame the bus refuses is lost and counted, the plant runs on
            bus = simulated.config
            simulated.router = start_router(simulated.bus, keep_sending=True, timeout=0.2,
                                            classical=None if bus.fd else bus.name,
                                            describe=bus.frame_owner)
            for drive in simulated.drives:
                drive.attach(simulated.router)
                self._cycles.attached.add(drive)
        with self.lock:
            attach_sensors(self.sensors, self.force_torques, self.buses)

    def close(self) -> None:
        """Disable every drive (brakes on), stop heartbeats, release the buses."""
        self._stop.set()
        with self.lock:
            for drive in self.drives:
                drive.core.disable()
        for simulated in self.buses:
            for drive in simulated.drives:
                drive.detach()
                self._cycles.leave(drive)
            if simulated.router is not None:
                simulated.router.stop(1.0)
        close_sensors(self.sensors, self.force_torques)

    def stop(self) -> None:
        self._stop.set()

    # --- fault injection (hil.simulator.faults) ---------------------------------------------

    def configured(self, drive: DriveConfig) -> DriveProfile:
        """The drive of an entry of the config (:meth:`FaultInjection.configured`)."""
        return self._faults.configured(drive)

    def drive(self, bus: str, node_id: int) -> DriveProfile:
        """The drive that has ``node_id`` on ``bus`` now (:meth:`FaultInjection.drive`)."""
        return self._faults.drive(bus, node_id)

    def inject(self, kind: DriveFaultKind, drive: DriveProfile) -> None:
        """A drive fault of ``hil sim --fault``'s kinds (:meth:`FaultInjection.inject`)."""
        self._faults.inject(kind, drive)

    def sensor(self, name: str) -> SimulatedImu | SimulatedForceTorque:
        """The sensor of that name in the config (KeyError if none)."""
        found = [sensor for sensor in [*self.sensors, *self.force_torques]
                 if sensor.config.name == name]
        if not found:
            raise KeyError(f"no sensor '{name}'")
        return found[0]

    def silence(self, bus: str, node_id: int) -> None:
        """The drive of ``node_id`` leaves its bus (:meth:`inject`)."""
        self.inject(DriveFaultKind.SILENCE, self.drive(bus, node_id))

    def restart(self, bus: str, node_id: int) -> None:
        """The drive of ``node_id`` restarts as after a power cycle (:meth:`inject`)."""
        self.inject(DriveFaultKind.RESTART, self.drive(bus, node_id))

    def raise_fault(self, bus: str, node_id: int) -> None:
        """The drive of ``node_id`` faults as on a following error (:meth:`inject`)."""
        self.inject(DriveFaultKind.FAULT, self.drive(bus, node_id))

    # --- time -------------------------------------------------------------------

    def run(self, duration: float | None = None) -> None:
        """Run until :meth:`stop` (or ``duration`` seconds of plant time): check the watchdogs
        and send timed messages every WATCHDOG_PERIOD; in real time, plant time follows the
        wall clock meanwhile."""
        dt = self.plant.timestep
        end = None if duration is None else self.plant.time + duration - dt / 2
        with self.lock:
            if end is not None:
                self._real_time.last_step = math.ceil(end / dt)
            if not self.lock_step:
                self._real_time.start()
        try:
            while not self._stop.wait(WATCHDOG_PERIOD):
                if not self.lock_step:
                    self._note_stall(self.stalls.tick())
                self._check_watchdogs()
                if end is not None and self.now() >= end:
                    return
        finally:
            with self.lock:
                self._real_time.started = self._real_time.last_step = None

    def follow(self, clock: Callable[[], float]) -> None:
        """Real time on another clock, without :meth:`run`: from now on plant time follows
        ``clock`` (s) from its present reading, stepped whenever a frame or a call enters the
        lock; no watchdog and no timed message runs (a replay on a log's own timestamps).
        Real time only: a lock-step plant moves by cycles."""
        if self.lock_step:
            raise ValueError("a lock-step simulator's plant moves by cycles, not on a clock")
        with self.lock:
            self._real_time.wall_clock = clock
            self._real_time.start()

    def _note_stall(self, stall: Stall | None) -> None:
        if stall is not None and self.on_stall is not None:
            self.on_stall(stall)

    def now(self) -> float:
        """The plant's time (s); in real time, brought up to the present first."""
        with self.lock:
            return self.plant.time

    def _check_watchdogs(self) -> None:
        """Watchdogs and timed messages (heartbeats, cyclic rates), every WATCHDOG_PERIOD of
        wall-clock time in both modes."""
        now = time.monotonic()
        # the check's frames (every drive's due heartbeat) in one message, put once the lock
        # is left: one put each was a Zenoh message, and a wake-up of the controller's
        # receiving thread, a heartbeat (24 drives at hil init's 0.1 s: 240 a second)
        with held_together(self._batches), self.lock:
            for drive in self.drives:
                drive.core.check_watchdog(now)
                drive.after_update()
                drive.tick(now)

    # --- lock-step cycles (hil.simulator.cycles) ----------------------------------------------

    def close_cycle(self) -> None:
        """Lock-step: end this cycle now, whichever drives have had their command: the plant
        steps one control period and every drive sends its answers (a test's own step)."""
        with self.lock:
            self._cycles.close()

    def cycle_begun(self) -> bool:
        """Lock-step: whether a drive on its bus has had its command of the open cycle."""
        with self.lock:
            return self._cycles.begun()
