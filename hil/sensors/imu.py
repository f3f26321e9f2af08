"""A simulated IMU: at each of its sample times (plant time) it reads the plant's IMU at its
site, adds its product's errors (:mod:`.noise`) and sends the sample on its wire after its
latency. Called after every plant step, with the simulator's lock held, in real time and in
lock-step alike: its samples follow plant time, so a lock-step run's are the same every run.
"""

from __future__ import annotations

import functools
from collections import deque
from collections.abc import Callable
from typing import Generic, TypeVar

import numpy as np

from hil.bus_config.sensor_types import ImuConfig
from hil.can.faults import SensorFaultKind
from hil.can.frame import Frame
from hil.protocols import hipnuc, wit
from hil.protocols.imu import ImuSample
from hil.sensors.faults import SensorFaults
from hil.sensors.noise import TriadNoise
from hil.sensors.port import Port

Payload = TypeVar("Payload")

#: the plant's reading of an IMU: specific force, angular velocity, orientation (w, x, y, z)
Reading = Callable[[], tuple[np.ndarray, ...]]


def codec_of(config: ImuConfig) -> Callable[[ImuSample], bytes | list[Frame] | ImuSample]:
    """Its product's codec: a sample as its wire carries it (WitMotion's packets on a serial
    port, HiPNUC's TPDOs on a bus; a DM-IMU's sample as it is, which its port encodes as
    each request asks)."""
    if config.product == "wit":
        return functools.partial(wit.encode, outputs=config.outputs)
    if config.product == "hipnuc":
        return functools.partial(hipnuc.frames, node_id=config.node_id, outputs=config.outputs)
    return _as_it_is


def _as_it_is(sample: ImuSample) -> ImuSample:
    return sample


class SimulatedImu(Generic[Payload]):
    """One IMU of the bus config, sampling ``read`` from plant time ``start`` on, each sample
    made its wire's payload by its product's codec (:func:`codec_of`) and written to
    ``port``."""

    def __init__(self, config: ImuConfig, read: Reading, port: Port[Payload],
                 start: float = 0.0):
        self.config = config
        self._read = read
        self._encode = codec_of(config)
        self.port = port
        self._period = config.period           # read at every plant step: once
        accelerometer, gyroscope = np.random.default_rng(config.seed).spawn(2)
        self._accelerometer = TriadNoise(config.accelerometer, config.period, accelerometer)
        self._gyroscope = TriadNoise(config.gyroscope, config.period, gyroscope)
        self._start = start
        #: the next sample is due at start + this many periods: the first a period in
        self._samples = 1
        self._sending: deque[tuple[float, Payload]] = deque()   # (due, payload) in latency
        self.sent = 0
        self._faults = SensorFaults()
        self._frozen: Payload | None = None         # a frozen sensor's sample

    def inject(self, kind: SensorFaultKind, at: float) -> None:
        """Fail as ``kind`` says at plant time ``at`` (s): fall silent, freeze on the last
        sample, or send one sample at full scale."""
        self._faults.inject(kind, at)

    def after_step(self, now: float) -> None:
        """The plant is at ``now`` (s): take the samples due by then, send those whose
        latency is over."""
        period = self._period
        faults = self._faults
        # a step's time is a sum of floats: half a step's worth of slack, not a sample late
        while self._start + self._samples * period <= now + 1e-9:
            due = self._start + self._samples * period
            self._samples += 1
            was_silent = faults.silent
            spike = faults.reach(due)
            if faults.silent:
                if not was_silent:
                    self.port.fall_silent()
                self._sending.clear()
                return
            packets = self._sample(spike) if self._frozen is None else self._frozen
            if faults.freezing:
                self._frozen = packets
            self._sending.append((now + self.config.latency, packets))
        while self._sending and self._sending[0][0] <= now + 1e-9:
            self.port.write(self._sending.popleft()[1])
            self.sent += 1

    def _sample(self, spike: bool = False) -> Payload:
        acceleration, rate, orientation = self._read()
        if spike:               # past the range on every axis: the wire saturates it
            acceleration, rate = np.full(3, 1e6), np.full(3, 1e6)
        return self._encode(ImuSample(self._accelerometer.apply(acceleration),
                                      self._gyroscope.apply(rate), orientation))
