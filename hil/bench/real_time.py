"""Real-time runs of the in-process stack: the control cycle, bus load, latency, the
timing floor under them, and the same over SocketCAN vcan."""

from __future__ import annotations

import threading
import time

import can
import numpy as np

from hil.bench.settings import DID_NOT_START, ROBOTS, BenchSettings
from hil.bus_config import SystemConfig, load_bus_config
from hil.can import socketcan_missing
from hil.can.frames import BitRates
from hil.can.monitor import BusLoadMeter
from hil.messaging import cdr
from hil.messaging.samples import ControlSamples
from hil.messaging.zenoh_api import key
from hil.realtime import REAL_TIME, CyclePacer, PeriodStatistics
from hil.stack import IN_PROCESS, StackDidNotStart, running_stack


def real_time(config: SystemConfig, seconds: float) -> tuple[dict, dict, list[dict]]:
    """The control cycle's figures, the latency's and each bus' load over ``seconds`` of
    real time; if the stack did not start, a cycle row with :data:`DID_NOT_START`."""
    try:
        return _real_time(config, seconds)
    except StackDidNotStart as failure:
        return {DID_NOT_START: str(failure)}, {"unavailable": "the stack did not start"}, []


def _real_time(config: SystemConfig, seconds: float) -> tuple[dict, dict, list[dict]]:
    with running_stack(config, REAL_TIME) as stack:
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


def timing_floor(rate: float, seconds: float) -> dict:
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

    def __init__(self, channel: str, bus_name: str, bit_rates: BitRates):
        self.bus = can.Bus(interface=IN_PROCESS, channel=channel, fd=True)
        self.meter = BusLoadMeter({channel: (bus_name, bit_rates)}, time.time())
        self.delivery = self.bus.deliver_to([self.meter])

    def stop(self) -> None:
        self.delivery.stop()
        self.bus.shutdown()


def _listen(config: SystemConfig, channels: dict[str, str]) -> list[tuple[_Listener, object]]:
    return [(_Listener(channels[bus.name], bus.name, bus.bit_rates), bus) for bus in config.buses]


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
            stamp = cdr.seconds_of(cdr.decode(payload, cdr.JOINT_STATE).header.stamp)
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



def vcan_missing() -> str | None:
    missing = socketcan_missing(("vcan0", "vcan1"))
    return missing and (f"{missing}: create them with tools/vcan-setup.sh, or run the bench "
                        "inside tools/uml_run.py")


def socketcan(settings: BenchSettings) -> list[dict]:
    rows = []
    for robot in ROBOTS:
        config = load_bus_config(settings.config_dir / f"{robot}.yaml")
        channels = dict(zip((b.name for b in config.buses), ("vcan0", "vcan1")))
        row = {"robot": robot, "rate_hz": config.cycle_hz}
        try:
            with running_stack(config, REAL_TIME, "socketcan", channels) as stack:
                stack.node.statistics.clear()
                time.sleep(settings.seconds)
                row.update(stack.node.statistics.figures())
        except StackDidNotStart as failure:
            row[DID_NOT_START] = str(failure)
        rows.append(row)
    return rows

