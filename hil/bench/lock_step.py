"""Lock-step speed of the in-process stack, and the bare python-can exchange and bare MuJoCo
steps it is held against."""

from __future__ import annotations

import threading
import time
import uuid

import can
import numpy as np

from hil.bench.frames import cyclic_frames
from hil.bus_config import SystemConfig
from hil.plant import Plant
from hil.stack import IN_PROCESS, running_stack
from hil.realtime.timing import LOCK_STEP

#: lock-step: the run is also timed in windows this long (s), for its quiet quartile
LOCK_STEP_WINDOW = 0.02


def lock_step(config: SystemConfig, cycles: int) -> dict:
    """Speed-up over real time and time per cycle, over the whole run and over its fastest
    quarter of LOCK_STEP_WINDOW windows: on a shared machine a busy neighbour slows every
    cycle for hundreds of ms at a time, and the quiet quartile is what the code does alone."""
    windows = []                    # (cycles, wall seconds) per window
    with running_stack(config, LOCK_STEP) as stack:
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


def bare_python_can(config: SystemConfig, cycles: int) -> float:
    """Per cycle: the master's frames out and the drives' answers back on the stacks'
    in-process buses, delivered the same way (in the sender's thread), answered by a bare
    listener: no protocol, no physics, no control."""
    tag = uuid.uuid4().hex[:8]
    opened, exchanges = [], []
    for name, out, answers in cyclic_frames(config):
        channel = f"hil-bare-{tag}-{name}"
        master, drive = (can.Bus(interface=IN_PROCESS, channel=channel) for _ in range(2))
        opened += [master, drive]
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


def bare_mujoco(config: SystemConfig, cycles: int) -> float:
    plant = Plant(config.robot, timestep=1.0 / config.plant_rate_hz)
    torques = np.zeros(len(plant.actuator_names))
    started = time.perf_counter()
    for _ in range(cycles):
        plant.set_motor_torques(torques)
        plant.step(config.steps_per_cycle)
    return (time.perf_counter() - started) / cycles * 1e6

