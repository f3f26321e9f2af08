"""The simulated bench: the MuJoCo plant and every drive of a bus config.

Two time modes:

* real-time: plant time follows the wall clock. Whatever touches the plant
  or a drive (a frame arriving, a status read, the periodic watchdog check)
  enters :class:`PlantPresent`, which first steps the plant, with the drives'
  inner loops, up to the present; so a frame acts on and samples the state
  at its arrival, and no thread has to wake at the plant's rate (in one
  process such a thread fought the controller's for the GIL). Drives answer
  each cycle's command (SYNC, or a command frame) at once and send their
  timed messages when due;
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
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable
from contextlib import AbstractContextManager
from dataclasses import dataclass, replace

import can

from hil.bus_config import BusConfig, DriveConfig, SystemConfig
from hil.drives import DriveCore, DriveParameters, DriveProfile, Fault
from hil.can import deliver_under
from hil.can.faults import DriveFaultKind
from hil.can.frame import Frame
from hil.can.router import FrameRouter, start_router
from hil.drives.group import CoreGroup
from hil.drives.tuning import tuned_gains
from hil.errors import HilError
from hil.plant import Plant
from hil.protocols import protocol
from hil.realtime.present import PlantPresent
from hil.realtime.stalls import Stall, StallDetector
from hil.realtime.timing import REAL_TIME, Timing

log = logging.getLogger(__name__)

WATCHDOG_PERIOD = 0.01
#: real time: a gap longer than this (a stalled process) is skipped, not replayed (s)
MAX_CATCH_UP = 0.05
#: lock-step's shortest drive watchdog (s): a loaded machine stalls a process, which must not
#: fault a lock-step run (User-Mode Linux on a shared 2-core CI host: over 2 s seen)
LOCK_STEP_WATCHDOG = 10.0


def drive_parameters(drive: DriveConfig, motor_inertia: float) -> DriveParameters:
    """Drive parameters, with gains tuned to the motor-side inertia unless configured
    (:func:`hil.drives.tuning.tuned_gains`)."""
    gains = drive.gains
    if gains is None:
        position_kp, velocity_kp, velocity_ki = tuned_gains(
            motor_inertia, drive.velocity_bandwidth_hz, f"drive {drive.label}")
    else:
        position_kp, velocity_kp, velocity_ki = (gains.position_kp, gains.velocity_kp,
                                                 gains.velocity_ki)
    return DriveParameters(
        counts_per_rev=drive.encoder_counts_per_rev, rated_torque=drive.rated_torque,
        peak_torque=drive.peak_torque, position_kp=position_kp, velocity_kp=velocity_kp,
        velocity_ki=velocity_ki, max_velocity=drive.max_velocity,
        following_error_limit=(drive.following_error_limit
                               if protocol(drive.protocol).has_following_error else 0.0),
        following_error_timeout=drive.following_error_timeout,
        quick_stop_deceleration=drive.quick_stop_deceleration,
        watchdog_timeout=drive.watchdog_timeout, position_limits=drive.position_limits,
        holding_brake=drive.holding_brake,
        # profile moves (CiA 402 profile modes) until a master sets its own
        profile_velocity=drive.max_velocity / 4,
        profile_acceleration=drive.quick_stop_deceleration / 4,
        profile_deceleration=drive.quick_stop_deceleration / 4,
        no_load_speed=drive.effects.no_load_speed,
        velocity_filter=drive.effects.velocity_filter)


def bench_plant(config: SystemConfig) -> Plant:
    """The plant of a bus config: its robot at its plant rate, with its actuator effects, its
    scene, its base and its start pose."""
    return Plant(config.robot, timestep=1.0 / config.plant_rate_hz, effects=config.effects,
                 scene=config.scene, floating_base=config.floating_base,
                 start_pose=dict(config.start_pose))


@dataclass
class SimulatedBus:
    """One bus of the simulator: its config, python-can bus and drives (in config order)."""

    config: BusConfig
    bus: can.BusABC
    drives: list
    #: the drives' side of the bus (frames a bus refuses counted in its lost_frames);
    #: started by Simulator.start
    router: FrameRouter | None = None


class Simulator:
    """Plant + drives + buses. Start with :meth:`start`, end with :meth:`close`."""

    def __init__(self, config: SystemConfig, buses: dict[str, can.BusABC],
                 timing: Timing = REAL_TIME):
        self.config = config
        self.timing = timing
        self.lock_step = timing.lock_step       # read at every frame
        # lock-step: nothing moves the plant between commands, nothing to advance on entry
        # (a plain lock, cheaper a cycle: docs/performance.md, "2026-11-28, fourth step: a bus'
        # cycle in one send (issue 48)")
        self.lock: AbstractContextManager = (threading.RLock() if timing.lock_step
                                             else PlantPresent(self._advance))
        self.plant = bench_plant(config)
        self.steps_per_cycle = config.steps_per_cycle
        #: cycles run: lock-step, the plant's; real time, the most cycle frames (SYNCs,
        #: commands) any drive has had from its master, whoever the master is
        self.cycles = 0
        self._commands: dict[DriveProfile, int] = {}
        self.overruns = 0          # real time: gaps skipped (the process stalled)
        #: real time: the process' own stalls, found from the watchdog's wake-ups
        self.stalls = StallDetector("sim", WATCHDOG_PERIOD)
        #: called with each stall found (in the thread that runs :meth:`run`)
        self.on_stall: Callable[[Stall], None] | None = None
        self.wall_clock = time.perf_counter      # what plant time follows in real time
        # real time, while run() runs: plant steps done since the clock's epoch
        self._clock: tuple[float, int] | None = None      # (epoch, steps done)
        self._last_step: int | None = None                # run(duration): no step past it
        inertias = self.plant.motor_inertias()
        actuator_index = {name: i for i, name in enumerate(self.plant.actuator_names)}
        self.buses: list[SimulatedBus] = []
        self.drives = []
        #: (bus name, config entry, its drive) in the config's order: a drive by its entry
        self._entries: list[tuple[str, DriveConfig, DriveProfile]] = []
        #: each drive's core with its plant actuator index, walked at every plant step
        self._cores = CoreGroup(len(self.plant.actuator_names))
        for bus_config in config.buses:
            drives = []
            for drive_config in bus_config.drives:
                parameters = drive_parameters(drive_config, inertias[drive_config.actuator])
                if timing.lock_step and parameters.watchdog_timeout > 0:
                    parameters = replace(parameters, watchdog_timeout=max(
                        parameters.watchdog_timeout, LOCK_STEP_WATCHDOG))
                core = DriveCore(parameters)
                core.set_cycle(bus_config.cycle)
                drive = protocol(drive_config.protocol).drive_class()(drive_config, core,
                                                                      self.lock)
                drive.on_command = self._on_command
                drives.append(drive)
                self._entries.append((bus_config.name, drive_config, drive))
                self._cores.add(core, actuator_index[drive_config.actuator])
            self.buses.append(SimulatedBus(bus_config, buses[bus_config.name], drives))
            self.drives += drives
        self._waiting: set[DriveProfile] = set(self.drives)   # lock-step: no command yet
        #: the drives on their bus (attached by start, until silenced or closed), kept here:
        #: asking each drive (DriveProfile.attached) at every lock-step cycle costs a call a
        #: drive, and this set is the next cycle's waiting set as it is
        self._attached: set[DriveProfile] = set()
        self._stop = threading.Event()
        self._measure()

    # --- life cycle -------------------------------------------------------------

    def start(self) -> None:
        """Connect every drive to its bus: boot-up messages, heartbeats, cycle frames."""
        # a message of frames (a cycle's, over Zenoh) in one entry of the plant's lock
        deliver_under((simulated.bus for simulated in self.buses), self.lock)
        for simulated in self.buses:
            # the drives' side: a frame the bus refuses is lost and counted, the plant runs on
            simulated.router = start_router(simulated.bus, keep_sending=True, timeout=0.2)
            for drive in simulated.drives:
                drive.attach(simulated.router)
                self._attached.add(drive)

    def close(self) -> None:
        """Disable every drive (brakes on), stop heartbeats, release the buses."""
        self._stop.set()
        with self.lock:
            for drive in self.drives:
                drive.core.disable()
        for simulated in self.buses:
            for drive in simulated.drives:
                drive.detach()
                self._attached.discard(drive)
            if simulated.router is not None:
                simulated.router.stop(1.0)

    def stop(self) -> None:
        self._stop.set()

    # --- fault injection ------------------------------------------------------------

    def configured(self, drive: DriveConfig) -> DriveProfile:
        """The drive of an entry of the config, whatever node id an LSS master has given it
        since (CiA 305 configure node id)."""
        for _, entry, profile in self._entries:
            if entry == drive:
                return profile
        raise KeyError(f"no drive {drive.label} in {self.config.path}")

    def drive(self, bus: str, node_id: int) -> DriveProfile:
        """The drive that has ``node_id`` on ``bus`` now (LSS may have changed the config's);
        HilError where none has it, or two do (an LSS master gave a taken id: either would
        be a guess)."""
        with self.lock:
            on_bus = [(entry, profile) for name, entry, profile in self._entries if name == bus]
            found = [(entry, profile) for entry, profile in on_bus if profile.node_id == node_id]
        if len(found) == 1:
            return found[0][1]
        if not found:
            there = sorted({profile.node_id for _, profile in on_bus})
            raise HilError.single(f"no drive has node id {node_id} on bus '{bus}' now",
                                  self.config.path, hint="node ids there now: " + (
                                      ", ".join(map(str, there)) or "none (no such bus)"))
        joints = " and of ".join(", ".join(entry.joints) for entry, _ in found)
        raise HilError.single(f"node id {node_id} on bus '{bus}' is the drive of {joints} (an "
                              "LSS master gave it to each)", self.config.path,
                              hint="name the drive by its joint (DrivesBench.state/fault(JOINT))"
                                   ", or give each its own node id")

    def inject(self, kind: DriveFaultKind, drive: DriveProfile) -> None:
        """A drive fault (``hil sim --fault``'s kinds): ``silence``, it leaves its bus (its
        physics runs on); ``restart``, as after a power cycle (it boots again, unconfigured);
        ``fault``, as on a following error (it reports it in its protocol)."""
        with self.lock:
            if kind is DriveFaultKind.SILENCE:
                drive.detach()
                self._attached.discard(drive)
                self._waiting.discard(drive)
            elif kind is DriveFaultKind.RESTART:
                drive.restart()
            else:
                drive.core.raise_fault(Fault.FOLLOWING_ERROR)
                drive.after_update()

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
                self._last_step = math.ceil(end / dt)
            if not self.lock_step:
                self._clock = (self.wall_clock(), 0)
        try:
            while not self._stop.wait(WATCHDOG_PERIOD):
                if not self.lock_step:
                    self._note_stall(self.stalls.tick())
                self._check_watchdogs()
                if end is not None and self.now() >= end:
                    return
        finally:
            with self.lock:
                self._clock = self._last_step = None

    def follow(self, clock: Callable[[], float]) -> None:
        """Real time on another clock, without :meth:`run`: from now on plant time follows
        ``clock`` (s) from its present reading, stepped whenever a frame or a call enters the
        lock; no watchdog and no timed message runs (a replay on a log's own timestamps).
        Real time only: a lock-step plant moves by cycles."""
        if self.lock_step:
            raise ValueError("a lock-step simulator's plant moves by cycles, not on a clock")
        with self.lock:
            self.wall_clock = clock
            self._clock = (clock(), 0)

    def _note_stall(self, stall: Stall | None) -> None:
        if stall is not None and self.on_stall is not None:
            self.on_stall(stall)

    def now(self) -> float:
        """The plant's time (s); in real time, brought up to the present first."""
        with self.lock:
            return self.plant.time

    def _advance(self) -> None:
        """Real time (lock held): step the plant up to the wall clock. A gap over MAX_CATCH_UP
        is skipped and counted in :attr:`overruns`: the plant then lags the wall clock."""
        if self._clock is None:
            return
        epoch, done = self._clock
        dt = self.plant.timestep
        due = int((self.wall_clock() - epoch) / dt) - done
        if due > MAX_CATCH_UP / dt:
            self.overruns += 1
            epoch += (due - 1) * dt
            due = 1
        if self._last_step is not None:
            due = min(due, self._last_step - round(self.plant.time / dt))
        for _ in range(due):
            self._step()
        self._clock = (epoch, done + max(due, 0))

    def _step(self) -> None:
        """One plant step with the drives' inner loops (lock held)."""
        dt = self.plant.timestep
        self.plant.set_motor_torques(self._cores.update(dt))
        self.plant.step()
        self._measure(dt)
        for drive in self.drives:
            drive.after_update()

    def _measure(self, dt: float = 0.0) -> None:
        """Each drive's motor position and velocity now, ``dt`` after the last (0: the
        first)."""
        # Python floats: numpy scalars make every drive's loop arithmetic slower
        # (docs/performance.md, "2026-12-06, later: figures from code comments")
        self._cores.measure(self.plant.motor_positions().tolist(),
                            self.plant.motor_velocities().tolist(), dt)

    def _check_watchdogs(self) -> None:
        """Watchdogs and timed messages (heartbeats, cyclic rates), every WATCHDOG_PERIOD of
        wall-clock time in both modes."""
        now = time.monotonic()
        with self.lock:
            for drive in self.drives:
                drive.core.check_watchdog(now)
                drive.after_update()
                drive.tick(now)

    def _on_command(self, drive: DriveProfile) -> None:
        """A drive has its command of this cycle (called with the lock held)."""
        if not self.lock_step:
            drive.send_replies()
            count = self._commands[drive] = self._commands.get(drive, 0) + 1
            self.cycles = max(self.cycles, count)
            return
        self._waiting.discard(drive)
        if not self._waiting:       # else other drives have not had this cycle's command
            self._complete_cycle()

    def close_cycle(self) -> None:
        """Lock-step: end this cycle now, whichever drives have had their command: the plant
        steps one control period and every drive sends its answers (a test's own step)."""
        with self.lock:
            self._complete_cycle()

    def cycle_begun(self) -> bool:
        """Lock-step: whether a drive on its bus has had its command of the open cycle."""
        with self.lock:
            return not self._attached <= self._waiting

    def _complete_cycle(self) -> None:
        for _ in range(self.steps_per_cycle):
            self._step()
        self.cycles += 1
        self._waiting = set(self._attached)
        self._send_replies()

    def _send_replies(self) -> None:
        """Lock-step: every drive's reply, in config order, those of a bus in one send
        (a profile that sends its own, in its place)."""
        attached = self._attached
        for simulated in self.buses:
            replies: list[Frame] = []
            for drive in simulated.drives:
                frames = drive.take_replies()
                if frames is None:
                    if replies:
                        simulated.router.send_frames(replies)
                        replies = []
                    drive.send_replies()
                elif drive in attached:
                    replies += frames
            if replies:
                simulated.router.send_frames(replies)
