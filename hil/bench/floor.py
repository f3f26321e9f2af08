"""The floor under ``hil bench``'s across-processes runs, measured in the same bench run.

The same frames per cycle (every drive's cyclic frames and the bus' cycle-end frames out,
their answers back, per bus) exchanged between two processes over the same transport,
python-can on both ends and no hil code on the answering side, paced like the controller,
each end on the CPU of the process it stands for (in lock-step, both on one CPU, as
``hil up --lock-step`` places sim and controller). The ratio stack / floor says what hil
adds to the transport.
Both ends send a cycle's frames as hil's do: together, one message per process and direction
(the master in ``held_together``, the answers from inside their delivery).

The answering process is :mod:`hil.bench.responder`. Each end's CPU share over the cycling
is reported too (``cpu``: ``sim`` the answering process, ``control`` the master's, the
bench process with every thread it has), the part of a CPU the transport alone takes beside
what ``hil sim`` and ``hil control`` take.
"""

from __future__ import annotations

import contextlib
import json
import os
import subprocess
import sys
import threading
import time
from collections.abc import Iterator

import can

from hil.bench.frames import cyclic_frames
from hil.bus_config import SystemConfig
from hil.can import batches, held_together
from hil.hardware.exchange import LOCK_STEP_REPLY_TIMEOUT
from hil.realtime import (CyclePacer, PeriodStatistics, Ring, enter_real_time, lock_step_cpus,
                          real_time_cpus)
from hil.zenoh_session import free_loopback_port


def floor_across_processes(config: SystemConfig, seconds: float, paced: bool = True) -> dict:
    """The config's frames per cycle between this process (paced like the controller, or
    unpaced as in lock-step: each cycle as soon as the last one's answers are in) and a bare
    answering process, over Zenoh on loopback: round trip last frame -> last answer;
    unpaced, also the speed-up over real time the exchange alone allows."""
    endpoint = f"tcp/127.0.0.1:{free_loopback_port()}"
    channels = {bus.name: f"bench-floor/{os.getpid()}/{bus.name}" for bus in config.buses}
    sim_cpus, control_cpus, _ = real_time_cpus() if paced else lock_step_cpus()
    spec = json.dumps({"endpoint": endpoint, "seconds": seconds + 30, "real_time": paced,
                       "cpus": sorted(sim_cpus or ()), "buses": [
        {"channel": channels[name], "trigger": out[-1].arbitration_id,
         "answers": [[a.arbitration_id, len(a.data), a.is_extended_id] for a in answers]}
        for name, out, answers in cyclic_frames(config)]})
    responder = subprocess.Popen([sys.executable, "-m", "hil.bench.responder", spec],
                                 stdout=subprocess.PIPE, text=True, start_new_session=True)
    try:
        if "ready" not in (responder.stdout.readline() or ""):
            raise RuntimeError("the floor's answering process did not start")
        if paced:
            return run_paced_master(config, channels, endpoint, seconds, control_cpus, paced,
                                    responder.pid)
        with _threads_on(control_cpus):     # as `hil control --cpus` keeps all of its own
            return run_paced_master(config, channels, endpoint, seconds, None, paced,
                                    responder.pid)
    finally:
        responder.terminate()
        responder.wait(10)


@contextlib.contextmanager
def _threads_on(cpus: set[int] | None) -> Iterator[None]:
    """Every thread of this process (Zenoh's, started by earlier runs, too) kept on ``cpus``
    meanwhile, then back where each was: the floor's master placed as the process it stands
    for. None: as they are."""
    if not cpus:
        yield
        return

    def each_thread(place) -> None:
        for tid in map(int, os.listdir("/proc/self/task")):
            with contextlib.suppress(OSError):      # a thread that ended meanwhile
                place(tid)

    here = os.sched_getaffinity(0)
    before: dict[int, set[int]] = {}
    each_thread(lambda tid: before.setdefault(tid, os.sched_getaffinity(tid)))
    each_thread(lambda tid: os.sched_setaffinity(tid, cpus))
    try:
        yield
    finally:        # a thread started meanwhile: where this one was
        each_thread(lambda tid: os.sched_setaffinity(tid, before.get(tid, here)))


def cpu_seconds(pid: int) -> float:
    """The CPU time (user and system, s) process ``pid`` has taken, all its threads."""
    with open(f"/proc/{pid}/stat") as stat:
        fields = stat.read().rpartition(")")[2].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def run_paced_master(config: SystemConfig, channels: dict[str, str], endpoint: str,
                     seconds: float, cpus: set[int] | None, paced: bool, answerer: int,
                     master: PacedMaster | None = None) -> dict:
    """The config's cyclic frames sent from this process on ``channels`` (Zenoh, at
    ``endpoint``) for ``seconds``, each cycle's answers awaited (:func:`paced_exchange`); the
    answering process is ``answerer`` (its CPU share is ``sim``'s). A ``master`` hears every
    frame, brings the drives up first and rewrites the cyclic frames between cycles; then
    only the cycle's answers are counted, and the measurement starts after its warm-up."""
    fd = {bus.name: bus.fd for bus in config.buses}
    buses = {name: can.Bus(interface="zenoh", channel=channel, connect=[endpoint], fd=fd[name])
             for name, channel in channels.items()}
    result: dict = {}
    try:
        cyclic = cyclic_frames(config)
        exchanges = [(buses[name], out, len(answers)) for name, out, answers in cyclic]
        expected = sum(count for *_, count in exchanges)
        counter = AnswerCounter(None if master is None else {
            answer.arbitration_id for *_, answers in cyclic for answer in answers})
        for bus in buses.values():
            bus.deliver_to([counter] if master is None else [counter, master])
        time.sleep(1.0)                               # the sessions find each other
        runs = [(seconds, result)]
        if master is not None:
            master.start({name: (buses[name], out) for name, out, _ in cyclic})
            runs.insert(0, (master.warm_up, {}))
        for length, figures in runs:
            thread = threading.Thread(target=paced_exchange, args=(
                exchanges, expected, counter, 1.0 / config.cycle_hz, length, figures, cpus,
                paced, {"sim": answerer, "control": os.getpid()}))
            thread.start()
            thread.join()
    finally:
        for bus in buses.values():
            bus.shutdown()
    return result


class PacedMaster(can.Listener):
    """A master on :func:`run_paced_master`'s loop: it hears every frame."""

    #: how long it cycles before the measurement starts (s): its drives coming up
    warm_up = 0.0

    def start(self, cycle: dict[str, tuple[can.BusABC, list[can.Message]]]) -> None:
        """Before the first cycle: each bus, by name, with the messages the loop sends on
        it every cycle (the master may rewrite their data between cycles)."""


def paced_exchange(exchanges, expected: int, counter: AnswerCounter, period: float,
                   seconds: float, result: dict, cpus: set[int] | None, paced: bool,
                   processes: dict[str, int]) -> None:
    """In a thread of its own, as the controller's loop: write the cycle (each exchange's
    messages as they are then: :mod:`hil.bench.bare_master` rewrites them between cycles),
    then the answers to it are due before the next one (paced), or the next cycle goes as
    soon as they are in (unpaced: lock-step, where a reply may take the controller's 2 s).
    ``processes``: the pids whose CPU share over the cycling goes in the result, by the name
    each stands for."""
    if paced:
        enter_real_time(cpus=cpus)
    statistics = PeriodStatistics(period)
    trips, late = Ring(PeriodStatistics.KEEP), 0
    pacer = CyclePacer(period, statistics) if paced else None
    wait = period if paced else LOCK_STEP_REPLY_TIMEOUT
    start = time.perf_counter()
    cpu_start = {name: cpu_seconds(pid) for name, pid in processes.items()}
    end, cycles = start + seconds, 0
    blocks = batches(bus for bus, _, _ in exchanges)       # as the controller: asked once
    try:
        while time.perf_counter() < end:
            if pacer is not None:
                pacer.release()
            cycles += 1
            counter.expect(expected)
            with held_together(blocks):                 # as the controller sends
                for bus, out, _ in exchanges:
                    for frame in out:
                        bus.send(frame)
            sent = time.perf_counter()
            arrived = counter.wait(sent + wait)
            if arrived is None:
                late += 1
            else:
                trips.add(arrived - sent)
    finally:
        if pacer is not None:
            pacer.close()
    wall = time.perf_counter() - start
    cpu = {name: round((cpu_seconds(pid) - cpu_start[name]) / wall, 3)
           for name, pid in processes.items()}
    figures = statistics.figures() if paced else {
        "cycles": cycles, "speedup_over_real_time": cycles * period / wall}
    result.update({**figures, **trips.percentiles_us("round_trip"), "late": late, "cpu": cpu})


class AnswerCounter(can.Listener):
    """Counts a cycle's answers (every frame, or those of ``identifiers``); :meth:`wait`
    returns when the last one arrived."""

    def __init__(self, identifiers: set[int] | None = None):
        self._identifiers = identifiers
        self._arrived = threading.Condition()
        self._count = self._expected = 0
        self._last = 0.0

    def expect(self, count: int) -> None:
        with self._arrived:
            self._count, self._expected = 0, count

    def on_message_received(self, msg: can.Message) -> None:
        if self._identifiers is not None and msg.arbitration_id not in self._identifiers:
            return
        with self._arrived:
            self._count += 1
            if self._count == self._expected:
                self._last = time.perf_counter()
                self._arrived.notify()

    def wait(self, deadline: float) -> float | None:
        with self._arrived:
            if self._arrived.wait_for(lambda: self._count >= self._expected,
                                      max(0.0, deadline - time.perf_counter())):
                return self._last
        return None
