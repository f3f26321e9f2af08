"""``hil bench``: how fast and how faithful the stack is, measured in one run.

Every figure comes from the same process and the same minutes, so ratios
hold on a noisy machine. The stacks run in-process on ``hil-virtual``
(python-can's virtual bus, frames handed over in the sender's thread;
SocketCAN vcan where the kernel has it), with the real
simulator, CAN master, trajectory controller and Zenoh publications on
loopback.

Figures (each a list of rows; a figure that cannot be measured here says why):

* ``control_cycle``: real-time period statistics per robot and rate (period
  from release to release, busy time, the loop's scheduling), and the sim's
  real-time factor over the same run;
* ``timing_floor``: the same pacing with nothing to do, at the highest rate:
  what this machine's scheduler and timers allow any loop;
* ``socketcan``: the same over vcan, or why not;
* ``lock_step``: speed-up over real time, full-stack time per cycle;
* ``overhead``: that time against a bare python-can exchange of the same
  frames on the same kind of bus, and against the bare MuJoCo steps;
* ``latency``: from a setpoint leaving the trajectory controller to the
  joint state it causes arriving on Zenoh;
* ``tracking``: RMS and max error on a fixed trajectory, against MuJoCo's
  ideal position servo on the same model following the same reference;
* ``bus_load``: measured on the bus against the bitrate, with the config's
  worst-case estimate;
* ``fault_detection``: for each injected fault kind, whether and how fast
  the controller reported it;
* ``across_processes``: ``hil sim`` and ``hil control`` (and ``hil viz``) as separate
  processes over the Zenoh CAN transport, beside the floor of that transport measured in
  the same run (:mod:`hil.bench_processes`).

``run_soak`` repeats a trajectory for a long time and reports drift, memory
growth and missed cycles.
"""

from __future__ import annotations

import math
import os
import platform
import tempfile
import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import can
import mujoco
import numpy as np

import hil.drives.core as core_module
from hil.bench_processes import config_at, floor_across_processes, stack_across_processes
from hil.bus_config import SystemConfig, load_bus_config
from hil.can import socketcan_missing
from hil.can.faults import FrameFault
from hil.can.monitor import BusLoadMeter
from hil.compiled import is_compiled
from hil.controllers import GoalRejected, TrajectoryGoal, TrajectoryPoint
from hil.messaging import types as T
from hil.messaging.samples import ControlSamples
from hil.messaging.zenoh_api import RunSubscriber, TrajectoryActionClient, key
from hil.plant import Plant
from hil.realtime import CyclePacer, PeriodStatistics
from hil.resources import BUS_CONFIGS, data_dir
from hil.simulator import motor_inertias
from hil.stack import IN_PROCESS, running_stack
from hil.zenoh_session import close_all

ROBOTS = ("ur3", "pigot")
RATES = (250.0, 500.0, 1000.0)
#: the figures every report has (a row list, or {"unavailable": why})
FIGURES = ("control_cycle", "timing_floor", "socketcan", "lock_step", "overhead", "latency",
           "tracking", "bus_load", "fault_detection", "across_processes")
#: across processes: (robot, rate) pairs, each with and without the visualiser
ACROSS_PROCESSES = tuple((robot, rate) for robot in ROBOTS for rate in (500.0, 1000.0))
ACROSS_PROCESSES_QUICK = (("ur3", 500.0),)


@dataclass(frozen=True)
class BenchSettings:
    seconds: float = 10.0          # per real-time run
    lock_step_cycles: int = 20000
    bare_cycles: int = 5000
    config_dir: Path = field(default_factory=lambda: data_dir(BUS_CONFIGS))
    across_processes: tuple[tuple[str, float], ...] = ACROSS_PROCESSES

    @classmethod
    def quick(cls, config_dir: Path | None = None) -> BenchSettings:
        return cls(seconds=2.0, lock_step_cycles=600, bare_cycles=1000,
                   across_processes=ACROSS_PROCESSES_QUICK,
                   **({"config_dir": config_dir} if config_dir else {}))


def run_bench(settings: BenchSettings, say: Callable[[str], None] = print) -> dict:
    """Measure every figure; raises RuntimeError if one is missing from the report."""
    report: dict = {"machine": {"cpus": len(os.sched_getaffinity(0)),
                                "python": platform.python_version(),
                                "platform": platform.platform(),
                                # setup.py compiles it where it can: the figures depend on it
                                "drive_core": "compiled" if is_compiled(core_module)
                                              else "interpreted"},
                    "settings": {"seconds": settings.seconds,
                                 "lock_step_cycles": settings.lock_step_cycles}}
    for name in FIGURES:
        report[name] = []
    say(f"hil bench: the timing floor (an empty loop at {max(RATES):g} Hz) ...")
    report["timing_floor"].append(_timing_floor(max(RATES), settings.seconds))
    for robot in ROBOTS:
        config = load_bus_config(settings.config_dir / f"{robot}.yaml")
        for rate in RATES:
            say(f"hil bench: {robot} real time at {rate:g} Hz ...")
            cycle, latency, loads = _real_time(with_rate(config, rate), settings.seconds)
            report["control_cycle"].append({"robot": robot, "rate_hz": rate,
                                            "transport": IN_PROCESS, **cycle})
            report["latency"].append({"robot": robot, "rate_hz": rate, **latency})
            report["bus_load"] += [{"robot": robot, "rate_hz": rate, **load} for load in loads]
        say(f"hil bench: {robot} lock-step, bare python-can, bare MuJoCo ...")
        lock_step = _lock_step(config, settings.lock_step_cycles)
        report["lock_step"].append({"robot": robot, "rate_hz": config.cycle_hz, **lock_step})
        bare_can = _bare_python_can(config, settings.bare_cycles)
        bare_mujoco = _bare_mujoco(config, settings.bare_cycles)
        full = lock_step["cycle_us"]
        report["overhead"].append({
            "robot": robot, "full_stack_cycle_us": full, "bare_python_can_cycle_us": bare_can,
            "bare_mujoco_cycle_us": bare_mujoco, "ratio_to_python_can": full / bare_can,
            "ratio_to_mujoco": full / bare_mujoco})
        say(f"hil bench: {robot} tracking against MuJoCo's ideal position servo ...")
        report["tracking"].append({"robot": robot, **_tracking(config)})
    say("hil bench: fault detection (ur3, 500 Hz) ...")
    report["fault_detection"] = _fault_detection(
        load_bus_config(settings.config_dir / "ur3.yaml"))
    missing = _vcan_missing()
    report["socketcan"] = {"unavailable": missing} if missing else _socketcan(settings)
    close_all()
    report["across_processes"] = _across_processes(settings, say)
    absent = [name for name in FIGURES if not report.get(name)]
    if absent:
        raise RuntimeError(f"figures missing from the report: {', '.join(absent)}")
    return report


def _across_processes(settings: BenchSettings, say: Callable[[str], None]) -> list[dict]:
    rows = []
    with tempfile.TemporaryDirectory(prefix="hil-bench-configs-") as folder:
        for robot, rate in settings.across_processes:
            path = config_at(settings.config_dir / f"{robot}.yaml", rate, Path(folder))
            say(f"hil bench: {robot} at {rate:g} Hz across processes: the floor ...")
            floor = floor_across_processes(load_bus_config(path), settings.seconds)
            for viz in (False, True):
                say(f"hil bench: {robot} at {rate:g} Hz across processes"
                    f"{', with the visualiser recording' if viz else ''} ...")
                stack = stack_across_processes(path, settings.seconds, viz)
                rows.append({"robot": robot, "rate_hz": rate, "viz": viz, **stack,
                             "floor": floor, "round_trip_p99_over_floor":
                             stack.get("round_trip_p99_us", math.nan)
                             / floor.get("round_trip_p99_us", math.nan)})
    return rows


def with_rate(config: SystemConfig, rate: float) -> SystemConfig:
    """The same bench with every bus at ``rate`` Hz."""
    return replace(config, buses=tuple(replace(bus, cycle_hz=rate) for bus in config.buses))


# --- stacks (hil.stack) -------------------------------------------------------------------


def _real_time(config: SystemConfig, seconds: float) -> tuple[dict, dict, list[dict]]:
    with running_stack(config, lock_step=False) as stack:
        meters = _listen(config, stack.channels)
        latency = _LatencyProbe(stack.zenoh, config.robot.name)
        stack.node.statistics.clear()
        plant_start, wall_start = stack.sim.now(), time.perf_counter()
        for meter, _ in meters:
            meter.meter.take(time.time())
        time.sleep(seconds)
        plant, wall = stack.sim.now() - plant_start, time.perf_counter() - wall_start
        loads = [(meter.meter.take(time.time()), bus) for meter, bus in meters]
        cycle = stack.node.statistics.figures()
        latency.close()
        for meter, _ in meters:
            meter.stop()
    cycle.update(sim_real_time_factor=plant / wall, faults=len(stack.node.faults))
    rows = []
    for measured, bus in loads:
        estimate = bus.load()
        for load in measured:
            if load.bus == bus.name:
                rows.append({"bus": bus.name, "bitrate": bus.bitrate,
                             "measured_frames_per_s": load.frames_per_second,
                             "measured_load": load.nominal,
                             "measured_load_worst_stuffing": load.worst_case,
                             "estimated_load_worst": estimate.worst_ratio})
    return cycle, latency.figures(1.0 / config.cycle_hz), rows


def _timing_floor(rate: float, seconds: float) -> dict:
    """The stacks' pacing with no work in the cycle, in a thread of its own."""
    statistics = PeriodStatistics(1.0 / rate)

    def loop() -> None:
        pacer = CyclePacer(1.0 / rate, statistics)
        end = time.perf_counter() + seconds
        try:
            while time.perf_counter() < end:
                pacer.release()
        finally:
            pacer.close()

    thread = threading.Thread(target=loop, name="timing floor")
    thread.start()
    thread.join()
    return {"rate_hz": rate, **statistics.figures()}


class _Listener:
    """A third bus on a channel with a load meter, fed in the sender's thread as the stack's
    own buses are (a Notifier thread waking for each frame would compete with the loop)."""

    def __init__(self, channel: str, bus_name: str, bitrate: int):
        self.bus = can.Bus(interface=IN_PROCESS, channel=channel)
        self.meter = BusLoadMeter({channel: (bus_name, bitrate)}, time.time())
        self.delivery = self.bus.deliver_to([self.meter])

    def stop(self) -> None:
        self.delivery.stop()
        self.bus.shutdown()


def _listen(config: SystemConfig, channels: dict[str, str]) -> list[tuple[_Listener, object]]:
    return [(_Listener(channels[bus.name], bus.name, bus.bitrate), bus) for bus in config.buses]


class _LatencyProbe:
    """Setpoint out of the controller (a cycle's sample time) to the joint state measured
    one cycle later arriving here on Zenoh.

    It subscribes on the stack's own session, where Zenoh calls it in the publishing
    thread: the control loop's. So it only keeps what arrived and when; decoding waits for
    :meth:`figures`, after the run."""

    def __init__(self, zenoh, robot: str):
        self._batches: list[bytes] = []
        self._states: list[tuple[bytes, float]] = []       # (payload, arrival)
        self._subscribers = [
            zenoh.declare_subscriber(key(robot, "control/samples"),
                                     lambda sample: self._batches.append(
                                         sample.payload.to_bytes())),
            zenoh.declare_subscriber(key(robot, "joint_states"),
                                     lambda sample: self._states.append(
                                         (sample.payload.to_bytes(), time.time())))]

    def figures(self, period: float) -> dict:
        if not self._batches or not self._states:
            return {"unavailable": "no joint states or samples arrived"}
        times = np.concatenate([ControlSamples.decode(batch).wall_time
                                for batch in self._batches])
        latencies = []
        for payload, arrival in self._states:
            stamp = T.seconds_of(T.decode(payload, T.JOINT_STATE).header.stamp)
            cycle = np.searchsorted(times, stamp) - 1      # the cycle that published it
            if 1 <= cycle < len(times):
                latencies.append(arrival - times[cycle - 1])   # its state came from cycle-1
        values = np.array(latencies) * 1e3
        return {"samples": len(values), "p50_ms": float(np.percentile(values, 50)),
                "p99_ms": float(np.percentile(values, 99)), "max_ms": float(values.max()),
                "cycle_ms": period * 1e3}

    def close(self) -> None:
        for subscriber in self._subscribers:
            subscriber.undeclare()


#: lock-step: the run is also timed in windows this long (s), for its quiet quartile
LOCK_STEP_WINDOW = 0.02


def _lock_step(config: SystemConfig, cycles: int) -> dict:
    """Speed-up over real time and time per cycle, over the whole run and over its fastest
    quarter of LOCK_STEP_WINDOW windows: on a shared machine a busy neighbour slows every
    cycle for hundreds of ms at a time, and the quiet quartile is what the code does alone."""
    windows = []                    # (cycles, wall seconds) per window
    with running_stack(config, lock_step=True) as stack:
        start_cycle, plant_start = stack.node.cycles, stack.sim.now()
        wall_start = time.perf_counter()
        last_cycle, last_wall = start_cycle, wall_start
        while last_cycle - start_cycle < cycles:
            time.sleep(LOCK_STEP_WINDOW)
            cycle, now = stack.node.cycles, time.perf_counter()
            windows.append((cycle - last_cycle, now - last_wall))
            last_cycle, last_wall = cycle, now
        done = stack.node.cycles - start_cycle
        wall, plant = time.perf_counter() - wall_start, stack.sim.now() - plant_start
    per_cycle = sorted(seconds / count for count, seconds in windows if count)
    quiet = float(np.mean(per_cycle[:max(1, len(per_cycle) // 4)]))
    return {"cycles": done, "speedup_over_real_time": plant / wall,
            "cycle_us": wall / done * 1e6, "windows": len(per_cycle),
            "speedup_quiet_quartile": 1.0 / config.cycle_hz / quiet,
            "cycle_us_quiet_quartile": quiet * 1e6}


def _bare_python_can(config: SystemConfig, cycles: int) -> float:
    """Per cycle: the master's frames out and the drives' answers back on the stacks'
    in-process buses, delivered the same way (in the sender's thread), answered by a bare
    listener: no protocol, no physics, no control."""
    tag = uuid.uuid4().hex[:8]
    opened, exchanges = [], []
    for bus in config.buses:
        channel = f"hil-bare-{tag}-{bus.name}"
        master, drive = (can.Bus(interface=IN_PROCESS, channel=channel) for _ in range(2))
        opened += [master, drive]
        out, answers = [], []                # the cyclic frames, by who sends them
        for drive_config in bus.drives:
            master_ids = _master_ids(bus, drive_config)
            for i, n, rate in bus.frames(drive_config):
                if rate == bus.cycle_hz:
                    (out if i in master_ids else answers).append(
                        can.Message(arbitration_id=i, data=bytes(n), is_extended_id=False))
        if bus.uses_sync:
            out.append(can.Message(arbitration_id=0x080, data=b"", is_extended_id=False))
        drive.deliver_to([_Responder(drive, out[-1].arbitration_id, answers)])
        exchanges.append((master, out, len(answers)))
    answered = _AnswerCounter()
    for master, *_ in exchanges:
        master.deliver_to([answered])
    expected = sum(count for *_, count in exchanges)
    started = time.perf_counter()
    for cycle in range(1, cycles + 1):
        for master, out, _ in exchanges:
            for frame in out:
                master.send(frame)
        answered.wait_for(cycle * expected)
    elapsed = time.perf_counter() - started
    for bus in opened:
        bus.shutdown()
    return elapsed / cycles * 1e6


class _Responder(can.Listener):
    """The bare drives of one bus: every cycle's answers, on the cycle's last frame."""

    def __init__(self, bus: can.BusABC, trigger: int, answers: list[can.Message]):
        self.bus, self.trigger, self.answers = bus, trigger, answers

    def on_message_received(self, msg: can.Message) -> None:
        if msg.arbitration_id == self.trigger:
            for answer in self.answers:
                self.bus.send(answer)


class _AnswerCounter(can.Listener):
    def __init__(self):
        self.count = 0
        self._arrived = threading.Condition()

    def on_message_received(self, msg: can.Message) -> None:
        with self._arrived:
            self.count += 1
            self._arrived.notify()

    def wait_for(self, count: int) -> None:
        with self._arrived:
            if not self._arrived.wait_for(lambda: self.count >= count, timeout=1.0):
                raise RuntimeError(f"bare exchange: {self.count} of {count} answers")


def _master_ids(bus, drive) -> set[int]:
    """Ids of a drive's cyclic frames that the master sends (CiA 402 RPDO, MIT command,
    ODrive Set_Input_Pos): the lowest id of the cyclic exchange's first frame."""
    cyclic = [f for f in bus.frames(drive) if f[2] == bus.cycle_hz]
    return {cyclic[0][0]}


def _bare_mujoco(config: SystemConfig, cycles: int) -> float:
    plant = Plant(config.robot, timestep=1.0 / config.plant_rate_hz)
    torques = np.zeros(len(plant.actuator_names))
    started = time.perf_counter()
    for _ in range(cycles):
        plant.set_motor_torques(torques)
        plant.step(config.steps_per_cycle)
    return (time.perf_counter() - started) / cycles * 1e6


# --- tracking -----------------------------------------------------------------------------

def tracking_goal(config: SystemConfig) -> TrajectoryGoal:
    """The fixed reference: every driven joint out by 0.3 rad (or 40 % of a prismatic
    range) in 1.5 s, back in 1.5 s, stopping at each end (cubic)."""
    names, ends = [], []
    for joint in config.robot.driven_joints:
        names.append(joint.name)
        lower, upper = joint.limits.lower, joint.limits.upper
        span = 0.3 if joint.type.is_rotational else 0.4 * (upper - lower)
        start = min(max(0.0, lower), upper)
        ends.append(start + span if start + span <= upper else start - span)
    zeros = (0.0,) * len(names)
    starts = tuple(min(max(0.0, j.limits.lower), j.limits.upper)
                   for j in config.robot.driven_joints)
    return TrajectoryGoal(tuple(names), (TrajectoryPoint(1.5, tuple(ends), zeros),
                                         TrajectoryPoint(3.0, starts, zeros)))


def _tracking(config: SystemConfig) -> dict:
    """The full stack (lock-step) follows the goal; MuJoCo's position servo follows the
    same reference on the same model; both errors are measured at the joints."""
    goal = tracking_goal(config)
    with running_stack(config, lock_step=True) as stack:
        samples: list[ControlSamples] = []
        subscriber = RunSubscriber(stack.zenoh, config.robot.name, samples.append, lambda *_: None,
                                   lambda *_: None)
        client = TrajectoryActionClient(stack.zenoh, config.robot.name)
        # first bring every joint to the start of the reference
        start = TrajectoryGoal(goal.joint_names, (TrajectoryPoint(
            2.0, goal.points[-1].positions, (0.0,) * len(goal.joint_names)),))
        client.wait_result(client.send_goal(start), 120)
        first = stack.node.cycles
        goal_id = client.send_goal(goal)
        result = client.wait_result(goal_id, 120)
        time.sleep(0.3)
        subscriber.close()
        client.close()
    cycles = np.concatenate([np.arange(s.first_cycle, s.next_cycle) for s in samples])
    reference = np.concatenate([s.reference for s in samples])[cycles > first]
    position = np.concatenate([s.position for s in samples])[cycles > first]
    error = reference - position
    ideal = _ideal_servo(config, reference)
    return {"result": result.status.name.lower(), "joints": list(goal.joint_names),
            "rms": float(np.sqrt(np.mean(error ** 2))), "max": float(np.abs(error).max()),
            "ideal_servo_rms": float(np.sqrt(np.mean(ideal ** 2))),
            "ideal_servo_max": float(np.abs(ideal).max()),
            "rms_per_joint": [float(v) for v in np.sqrt(np.mean(error ** 2, axis=0))]}


def _ideal_servo(config: SystemConfig, reference: np.ndarray) -> np.ndarray:
    """Joint error of MuJoCo position actuators (kp = J w^2, kv = 2 J w at each drive's
    velocity bandwidth, motor torque limits kept) following ``reference`` (per cycle)."""
    plant = Plant(config.robot, timestep=1.0 / config.plant_rate_hz)
    model = plant.model
    inertia = motor_inertias(plant)
    for drive in config.drives:
        i = model.actuator(drive.actuator).id
        omega = 2 * math.pi * drive.velocity_bandwidth_hz
        kp, kv = inertia[drive.actuator] * omega ** 2, 2 * inertia[drive.actuator] * omega
        model.actuator_gainprm[i, 0] = kp
        model.actuator_biastype[i] = mujoco.mjtBias.mjBIAS_AFFINE
        model.actuator_biasprm[i, :3] = (0.0, -kp, -kv)
        model.actuator_ctrllimited[i] = 0
        model.actuator_forcelimited[i] = 1
        model.actuator_forcerange[i] = (-drive.peak_torque, drive.peak_torque)
    transmissions = plant.transmissions
    names = [j.name for j in config.robot.driven_joints]
    index = {name: i for i, name in enumerate(names)}
    plant.set_joint_positions(dict(zip(names, reference[0])))
    measured = [plant.joint_names.index(name) for name in names]
    errors = []
    for row in reference:
        motor = np.zeros(len(plant.actuator_names))
        for transmission in transmissions:
            joints = [index[j] for j in transmission.joints]
            values = transmission.joint_to_actuator_position(row[joints])
            for actuator, value in zip(transmission.actuators, values):
                motor[plant.actuator_names.index(actuator)] = value
        plant.set_motor_torques(motor)       # ctrl = the motor position reference
        plant.step(config.steps_per_cycle)
        errors.append(row - plant.joint_positions()[measured])
    return np.array(errors)


# --- faults and soak ---------------------------------------------------------------------

def _fault_detection(config: SystemConfig, timeout: float = 3.0) -> list[dict]:
    """Inject each fault kind into a running stack; how soon does the controller say so?"""
    first = config.buses[0]
    node_id = first.drives[1].node_id
    kinds = {
        "drop every frame": lambda sim, buses: buses[first.name].add(
            FrameFault("drop", first.name, 1.0)),
        "delay answers 200 ms": lambda sim, buses: buses[first.name].add(
            FrameFault("delay", first.name, 1.0, 0.2)),
        "corrupt payload bits": lambda sim, buses: buses[first.name].add(
            FrameFault("corrupt", first.name, 1.0)),
        "silence a drive": lambda sim, buses: sim.silence(first.name, node_id),
        "raise a drive fault": lambda sim, buses: sim.raise_fault(first.name, node_id),
    }
    rows = []
    for kind, inject in kinds.items():
        with running_stack(config, lock_step=False, injectable=True) as stack:
            time.sleep(0.2)
            reported = len(stack.node.faults)
            started = time.perf_counter()
            inject(stack.sim, stack.sim_buses)
            while len(stack.node.faults) == reported and time.perf_counter() - started < timeout:
                time.sleep(0.0005)
            elapsed = time.perf_counter() - started
            detected = len(stack.node.faults) > reported
            rows.append({"fault": kind, "detected": detected,
                         "detection_ms": elapsed * 1e3 if detected else None,
                         "first_report": str(stack.node.faults[reported]) if detected else None})
    return rows


def run_soak(seconds: float, settings: BenchSettings, robot: str = "ur3",
             say: Callable[[str], None] = print) -> dict:
    """Repeat the tracking trajectory for ``seconds`` in real time; report the drift of the
    final position, memory growth (this process' RSS) and missed cycles. A repetition that
    fails (a fault: the controller refuses or aborts) is counted with its reason, and the
    faults are reset before the next one."""
    config = load_bus_config(settings.config_dir / f"{robot}.yaml")
    goal = tracking_goal(config)
    repetitions = []
    with running_stack(config, lock_step=False) as stack:
        client = TrajectoryActionClient(stack.zenoh, config.robot.name)
        latest: list = [None]     # only the last joint state: the soak measures the stack
        subscriber = stack.zenoh.declare_subscriber(key(config.robot.name, "joint_states"),
                                              lambda sample: latest.__setitem__(0, sample))
        stack.node.statistics.clear()
        started = time.monotonic()
        rss_start = _rss_bytes()
        while time.monotonic() - started < seconds:
            try:
                result = client.wait_result(client.send_goal(goal), 60)
                outcome, reason = result.status.name.lower(), result.error_string
            except GoalRejected as exc:
                outcome, reason = "rejected", str(exc)
            if outcome != "succeeded":
                say(f"hil bench: soak repetition failed ({reason}); resetting faults")
                client.reset_faults()
            time.sleep(0.2)
            last = T.decode(latest[0].payload.to_bytes(), T.JOINT_STATE)
            final = dict(zip(last.name, last.position))
            error = max(abs(final[n] - p) for n, p in zip(goal.joint_names,
                                                          goal.points[-1].positions))
            repetitions.append({"t_s": time.monotonic() - started,
                                "result": outcome, "reason": reason,
                                "final_error": float(error), "rss_bytes": _rss_bytes(),
                                "missed_so_far": stack.node.statistics.missed})
            say(f"hil bench: soak {repetitions[-1]['t_s']:.0f} s: {outcome}"
                f", final error {error:.5f}, RSS {repetitions[-1]['rss_bytes'] / 1e6:.1f} MB")
        subscriber.undeclare()
        client.close()
        cycles = stack.node.statistics.count
    close_all()
    errors = [r["final_error"] for r in repetitions]
    return {"robot": robot, "seconds": seconds, "repetitions": len(repetitions),
            "failed": sum(r["result"] != "succeeded" for r in repetitions),
            "final_error_first": errors[0], "final_error_last": errors[-1],
            "final_error_max": max(errors), "rss_growth_bytes": _rss_bytes() - rss_start,
            # the first repetition warms up (first goal, first publications): growth after it
            # is what a long run would keep adding
            "rss_growth_after_first_bytes": (repetitions[-1]["rss_bytes"]
                                             - repetitions[0]["rss_bytes"]),
            "cycles": cycles, "missed": repetitions[-1]["missed_so_far"],
            "timeline": repetitions}


def _rss_bytes() -> int:
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


# --- SocketCAN ----------------------------------------------------------------------------

def _vcan_missing() -> str | None:
    missing = socketcan_missing(("vcan0", "vcan1"))
    return missing and (f"{missing}: create them with tools/vcan-setup.sh, or run the bench "
                        "inside tools/uml_run.py")


def _socketcan(settings: BenchSettings) -> list[dict]:
    rows = []
    for robot in ROBOTS:
        config = load_bus_config(settings.config_dir / f"{robot}.yaml")
        channels = dict(zip((b.name for b in config.buses), ("vcan0", "vcan1")))
        with running_stack(config, False, "socketcan", channels) as stack:
            stack.node.statistics.clear()
            time.sleep(settings.seconds)
            rows.append({"robot": robot, "rate_hz": config.cycle_hz,
                         **stack.node.statistics.figures()})
    return rows

