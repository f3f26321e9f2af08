"""``hil bench``, across processes: the stack as users run it, and the floor under it.

Each run starts ``hil sim`` and ``hil control`` (and, in the runs "with viz", ``hil viz``
recording a file and the CAN log) as separate processes on the Zenoh CAN transport over
loopback, in real time, placed on the CPUs as ``hil up`` places them, for a while, stops
them with SIGINT and reads the controller's own report (``hil control --report``): period
error, missed cycles, busy time, the round trip from each cycle's SYNC to its last answer,
faults; and each process' CPU share from /proc.

The floor, measured in the same bench run: the same frames per cycle (every drive's
cyclic frames and SYNC out, their answers back, per bus) exchanged between two processes
over the same transport, python-can on both ends and no hil code on the answering side,
paced like the controller, each end on the CPU of the process it stands for. The ratio
stack / floor says what hil adds to the transport.

Rates above a config's own are run on buses of proportionally higher bitrate (the load
stays what the config has at its rate; the transport has no bitrate of its own).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import can
import yaml

from hil.bus_config import SystemConfig
from hil.cli.common import cpus_option
from hil.realtime import CyclePacer, PeriodStatistics, Ring, enter_real_time, real_time_cpus
from hil.zenoh_session import free_loopback_port

#: how long a process may take to come up (s); a loaded 2-CPU machine needs some of it
START_TIMEOUT = 60.0
#: how long after the controller's banner the measurement starts (bring-up, first goal)
SETTLE = 2.0


def cyclic_frames(config: SystemConfig) -> list[tuple[str, list[can.Message], list[can.Message]]]:
    """Per bus: (name, the frames the master sends each cycle, the last of them the one
    the drives answer, and the answers). SYNC where the protocol uses it."""
    exchanges = []
    for bus in config.buses:
        out, answers = [], []
        for drive in bus.drives:
            cyclic = [f for f in bus.frames(drive) if f[2] == bus.cycle_hz]
            master_ids = {cyclic[0][0]}     # the master's frame is the exchange's first
            for can_id, size, _ in cyclic:
                frame = can.Message(arbitration_id=can_id, data=bytes(size),
                                    is_extended_id=False)
                (out if can_id in master_ids else answers).append(frame)
        if bus.uses_sync:
            out.append(can.Message(arbitration_id=0x080, data=b"", is_extended_id=False))
        exchanges.append((bus.name, out, answers))
    return exchanges


def config_at(path: Path, rate: float, folder: Path) -> Path:
    """The bus config at ``path`` with every bus at ``rate`` Hz (bitrates scaled with it),
    written into ``folder``."""
    data = yaml.safe_load(path.read_text())
    data["robot"] = str((path.parent / data["robot"]).resolve())
    for bus in data["buses"]:
        scale = rate / bus["cycle_hz"]
        bus["cycle_hz"] = rate
        if "bitrate" in bus and scale > 1:
            bus["bitrate"] = int(bus["bitrate"] * scale)
    written = folder / f"{path.stem}-{rate:g}hz.yaml"
    written.write_text(yaml.safe_dump(data))
    return written


class _Processes:
    """hil processes of one run; each one's CPU time from /proc."""

    def __init__(self, folder: Path):
        self.folder = folder
        self.running: dict[str, subprocess.Popen] = {}
        self._cpu_start: dict[str, float] = {}

    def start(self, name: str, arguments: list[str], banner: str) -> None:
        log = (self.folder / f"{name}.log").open("w")
        process = subprocess.Popen([sys.executable, "-m", "hil", *arguments], stdout=log,
                                   stderr=subprocess.STDOUT, start_new_session=True)
        self.running[name] = process
        deadline = time.monotonic() + START_TIMEOUT
        while banner not in self.log(name):
            if process.poll() is not None or time.monotonic() > deadline:
                raise RuntimeError(f"hil {name} did not start: {self.log(name)[-2000:]}")
            time.sleep(0.1)

    def log(self, name: str) -> str:
        return (self.folder / f"{name}.log").read_text()

    def mark_cpu(self) -> None:
        self._cpu_start = {name: _cpu_seconds(p.pid) for name, p in self.running.items()}

    def cpu_shares(self, seconds: float) -> dict[str, float]:
        """Each process' CPU time since :meth:`mark_cpu`, as a share of one CPU."""
        return {name: (_cpu_seconds(p.pid) - self._cpu_start.get(name, 0.0)) / seconds
                for name, p in self.running.items() if p.poll() is None}

    def stop(self, name: str, timeout: float = 30.0) -> None:
        process = self.running.get(name)
        if process is None or process.poll() is not None:
            return
        process.send_signal(signal.SIGINT)
        try:
            process.wait(timeout)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()

    def stop_all(self) -> None:
        for name in ("control", "viz", "sim"):
            self.stop(name)


def _cpu_seconds(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as stat:
        fields = stat.read().rpartition(")")[2].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def stack_across_processes(config_path: Path, seconds: float, with_viz: bool) -> dict:
    """One real-time run of ``hil sim`` + ``hil control`` (+ ``hil viz``) on the config."""
    sim_cpus, control_cpus, viz_cpus = real_time_cpus()
    with tempfile.TemporaryDirectory(prefix="hil-bench-") as folder:
        folder = Path(folder)
        endpoint = f"tcp/127.0.0.1:{free_loopback_port()}"
        report = folder / "control.json"
        processes = _Processes(folder)
        try:
            processes.start("sim", ["sim", str(config_path), "--listen", endpoint,
                                    "--status-period", "0", *cpus_option(sim_cpus)],
                            "hil sim:")
            if with_viz:
                processes.start("viz", ["viz", str(config_path), "--connect", endpoint,
                                        "--save", str(folder / "run.rrd"), "--can-log",
                                        str(folder / "run.can.log"), *cpus_option(viz_cpus)],
                                "hil viz:")
            processes.start("control", ["control", str(config_path), "--connect", endpoint,
                                        "--report", str(report), *cpus_option(control_cpus)],
                            "hil control:")
            time.sleep(SETTLE)
            processes.mark_cpu()
            time.sleep(seconds)
            cpu = processes.cpu_shares(seconds)
        finally:
            processes.stop_all()
        if not report.exists():
            raise RuntimeError(f"hil control wrote no report: {processes.log('control')[-2000:]}")
        figures = json.loads(report.read_text())
        recorded = _recorded(processes.log("viz")) if with_viz else None
    lost = sum(bus.get("lost", 0) for bus in figures.pop("buses", {}).values())
    return {**figures, "faults": len(figures.get("faults", [])),
            "first_fault": (figures.get("faults") or [None])[0], "frames_lost": lost,
            "cpu": {name: round(share, 3) for name, share in cpu.items()},
            **({"recorded": recorded} if recorded else {})}


def _recorded(viz_log: str) -> str | None:
    lines = [line for line in viz_log.splitlines() if "cycles in" in line]
    return lines[-1].removeprefix("hil viz: ").strip() if lines else None


# --- the floor -----------------------------------------------------------------------------

def floor_across_processes(config: SystemConfig, seconds: float) -> dict:
    """The config's frames per cycle between this process (paced like the controller) and a
    bare answering process, over Zenoh on loopback: round trip SYNC -> last answer."""
    endpoint = f"tcp/127.0.0.1:{free_loopback_port()}"
    channels = {bus.name: f"bench-floor/{os.getpid()}/{bus.name}" for bus in config.buses}
    sim_cpus, control_cpus, _ = real_time_cpus()
    spec = json.dumps({"endpoint": endpoint, "seconds": seconds + 30,
                       "cpus": sorted(sim_cpus or ()), "buses": [
        {"channel": channels[name], "trigger": out[-1].arbitration_id,
         "answers": [[a.arbitration_id, len(a.data)] for a in answers]}
        for name, out, answers in cyclic_frames(config)]})
    responder = subprocess.Popen([sys.executable, "-m", "hil.bench_processes", spec],
                                 stdout=subprocess.PIPE, text=True, start_new_session=True)
    try:
        if "ready" not in (responder.stdout.readline() or ""):
            raise RuntimeError("the floor's answering process did not start")
        return _run_floor_master(config, channels, endpoint, seconds, control_cpus)
    finally:
        responder.terminate()
        responder.wait(10)


def _run_floor_master(config: SystemConfig, channels: dict[str, str], endpoint: str,
                      seconds: float, cpus: set[int] | None) -> dict:
    buses = {name: can.Bus(interface="zenoh", channel=channel, connect=[endpoint])
             for name, channel in channels.items()}
    result: dict = {}
    try:
        exchanges = [(buses[name], out, len(answers))
                     for name, out, answers in cyclic_frames(config)]
        expected = sum(count for *_, count in exchanges)
        counter = _Counter()
        for bus in buses.values():
            bus.deliver_to([counter])
        time.sleep(1.0)                               # the sessions find each other
        thread = threading.Thread(target=_floor_loop, args=(
            exchanges, expected, counter, 1.0 / config.cycle_hz, seconds, result, cpus))
        thread.start()
        thread.join()
    finally:
        for bus in buses.values():
            bus.shutdown()
    return result


def _floor_loop(exchanges, expected: int, counter: _Counter, period: float, seconds: float,
                result: dict, cpus: set[int] | None) -> None:
    """In a thread of its own, as the controller's loop: write the cycle, then the answers
    to it are due before the next one."""
    enter_real_time(cpus=cpus)
    statistics = PeriodStatistics(period)
    trips, late = Ring(PeriodStatistics.KEEP), 0
    pacer = CyclePacer(period, statistics)
    end = time.perf_counter() + seconds
    try:
        while time.perf_counter() < end:
            pacer.release()
            counter.expect(expected)
            for bus, out, _ in exchanges:
                for frame in out:
                    bus.send(frame)
            sent = time.perf_counter()
            arrived = counter.wait(sent + period)
            if arrived is None:
                late += 1
            else:
                trips.add(arrived - sent)
    finally:
        pacer.close()
    result.update({**statistics.figures(), **trips.percentiles_us("round_trip"),
                   "late": late})


class _Counter(can.Listener):
    """Counts a cycle's answers; :meth:`wait` returns when the last one arrived."""

    def __init__(self):
        self._arrived = threading.Condition()
        self._count = self._expected = 0
        self._last = 0.0

    def expect(self, count: int) -> None:
        with self._arrived:
            self._count, self._expected = 0, count

    def on_message_received(self, msg: can.Message) -> None:
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


def _respond(spec: dict) -> None:
    """The floor's answering process: on each bus, the answers on the trigger frame."""
    enter_real_time(cpus=set(spec["cpus"]) or None)
    buses = []
    for bus_spec in spec["buses"]:
        bus = can.Bus(interface="zenoh", channel=bus_spec["channel"], listen=[spec["endpoint"]])
        answers = [can.Message(arbitration_id=i, data=bytes(n), is_extended_id=False)
                   for i, n in bus_spec["answers"]]

        def answer(msg: can.Message, bus=bus, answers=answers,
                   trigger=bus_spec["trigger"]) -> None:
            if msg.arbitration_id == trigger:
                for frame in answers:
                    bus.send(frame)

        bus.deliver_to([answer])
        buses.append(bus)
    print("ready", flush=True)
    try:
        time.sleep(spec["seconds"])
    finally:
        for bus in buses:
            bus.shutdown()


if __name__ == "__main__":
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    _respond(json.loads(sys.argv[1]))
