"""A simulated Net F/T (ATI's six-axis force-torque sensor system) on its bus: it answers each
request of its master with the plant's force and torque at its site as of that moment,
with its noise, in the layout :mod:`hil.protocols.ati_netft` gives; a bias command zeroes
the readings at the present load. Its handler runs in the bus' delivery, with the
simulator's lock held (in real time the plant is stepped up to the present first)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from hil.bus_config.sensor_types import ForceTorqueConfig
from hil.can.faults import SensorFaultKind
from hil.can.frame import Frame
from hil.can.router import FrameRouter
from hil.protocols import ati_netft
from hil.sensors.faults import SensorFaults
from hil.sensors.noise import TriadNoise

#: the plant's force (N) and torque (N·m) at the sensor's site, in its axes
Reading = Callable[[], tuple[np.ndarray, ...]]


class SimulatedForceTorque:
    """One Net F/T of the bus config; ``now`` gives the plant's time (s)."""

    def __init__(self, config: ForceTorqueConfig, read: Reading, now: Callable[[], float]):
        self.config = config
        self._read = read
        self._now = now
        force, torque = np.random.default_rng(config.seed).spawn(2)
        period = 1.0 / config.sample_hz
        self._force = TriadNoise(config.force, period, force)
        self._torque = TriadNoise(config.torque, period, torque)
        self._offsets = (np.zeros(3), np.zeros(3))        # set by a bias command
        self.router: FrameRouter | None = None
        self.device = f"Net F/T at 0x{config.base_id:03X} on bus '{config.bus}'"
        self.answered = 0
        self.refused = 0          # commands of a wrong length or an unknown code: ignored
        self._faults = SensorFaults()
        self._frozen: dict[int, list[Frame]] = {}     # a frozen sensor's answer, by request

    def inject(self, kind: SensorFaultKind, at: float) -> None:
        """Fail as ``kind`` says at plant time ``at`` (s): answer nothing more, answer every
        request as the first after it came, or answer one request at full scale."""
        self._faults.inject(kind, at)

    def attach(self, router: FrameRouter) -> None:
        """On its bus: listen to commands at its base identifier."""
        self.router = router
        router.subscribe(self.config.base_id, self._on_command)

    def _on_command(self, frame: Frame) -> None:
        data = frame.data
        # hil's choice where the manual is silent: a command frame of another length, or an
        # unknown code, is ignored (the sensor has nothing to say to it)
        if len(data) != 1 or data[0] not in ati_netft.COMMANDS or self.router is None:
            self.refused += 1
            return
        command = data[0]
        faults = self._faults
        spike = faults.reach(self._now())
        if faults.silent:
            return
        if command == ati_netft.BIAS:
            force, torque = self._measure()
            self._offsets = (self._offsets[0] + force, self._offsets[1] + torque)
        elif command in (ati_netft.LONG, ati_netft.SHORT):
            frames = self._frozen.get(command) or self._answer(command, spike)
            if faults.freezing:
                self._frozen.setdefault(command, frames)
            self.router.send_frames(frames)
            self.answered += 1

    def _measure(self, spike: bool = False) -> tuple[np.ndarray, np.ndarray]:
        force, torque = self._read()
        if spike:               # past the range on every axis: the counts saturate
            force, torque = np.full(3, 1e9), np.full(3, 1e9)
        return (self._force.apply(force) - self._offsets[0],
                self._torque.apply(torque) - self._offsets[1])

    def _answer(self, command: int, spike: bool) -> list[Frame]:
        config = self.config
        force, torque = self._measure(spike)
        sample = int(self._now() * config.sample_hz)      # its own counter, at its rate
        if command == ati_netft.LONG:
            return ati_netft.long_answer(
                config.base_id, ati_netft.counts(force, config.counts_per_force, 32),
                ati_netft.counts(torque, config.counts_per_torque, 32), ati_netft.STATUS_OK,
                sample)
        force_divisor, torque_divisor = config.short_divisors
        return ati_netft.short_answer(
            config.base_id,
            ati_netft.counts(force, config.counts_per_force / force_divisor, 16),
            ati_netft.counts(torque, config.counts_per_torque / torque_divisor, 16),
            ati_netft.STATUS_OK, sample)

    def close(self) -> None:
        """Leave the bus."""
        if self.router is not None:
            self.router.unsubscribe(self.config.base_id, self._on_command)
            self.router = None
