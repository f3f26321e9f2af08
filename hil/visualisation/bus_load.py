"""Each bus' load in a recording: rows of ``bus/load``, per bus its measured load (% of the
bitrate, nominal and worst-case stuffing) per second of bus time (:mod:`.bus_time`) and
`hil check`'s estimate beside it, sent in GROUPED chunks."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import rerun as rr

from hil.can.monitor import MeasuredLoad
from hil.visualisation.bus_time import BusTimeLoads
from hil.visualisation.columns import ScalarTable
from hil.visualisation.entities import GROUPED, RobotEntities


class BusLoadLog:
    """The loads of a robot's ``buses`` (the monitor names each as ``monitor_names`` say),
    beside each bus' estimate (a fraction of the bitrate)."""

    def __init__(self, entities: RobotEntities, buses: tuple[str, ...],
                 monitor_names: Mapping[str, str], estimates: Mapping[str, float]):
        self._entities = entities
        self._buses = buses
        self._monitor_names = monitor_names
        self._estimates = estimates
        #: (wall time, bus loads) rows waiting to be sent on bus time
        self._loads = BusTimeLoads()
        self._sent = -np.inf

    def log_static(self) -> None:
        self._entities.recording.log(f"{self._entities.root}/bus/load", rr.SeriesLines(names=[
            f"{bus} {what} [%]" for bus in self._buses
            for what in ("load", "load, worst-case stuffing", "hil check's worst case")]),
            static=True)

    def cycles(self, wall: np.ndarray, period: float) -> None:
        """Recorded control cycles: the bus' clock (:class:`.bus_time.BusTimeLoads`)."""
        self._loads.cycles(wall, period)

    def add(self, wall_time: float, loads: list[MeasuredLoad]) -> None:
        """The loads of these buses among ``loads``, each measured over its interval up to
        ``wall_time``."""
        by_bus = {self._monitor_names[load.bus]: load for load in loads
                  if load.bus in self._monitor_names}
        row = [100 * value for bus in self._buses if bus in by_bus
               for value in (by_bus[bus].nominal, by_bus[bus].worst_case)]
        if len(row) != 2 * len(self._buses):          # a bus not measured: none this time
            return
        interval = max(load.interval for load in by_bus.values())
        self._loads.add(wall_time - interval, wall_time, row)
        if wall_time - self._sent >= GROUPED:
            self.send(wall_time)

    def send(self, now: float, final: bool = False) -> None:
        """The rows ready (on bus time: :mod:`.bus_time`), as one chunk."""
        self._sent = now
        times, rows = self._loads.ready(now, final)
        if not rows:
            return
        measured = np.array(rows, dtype=np.float32).reshape(len(rows), -1, 2)
        estimates = np.array([100 * self._estimates.get(bus, np.nan) for bus in self._buses],
                             dtype=np.float32)          # beside each bus' pair, unscaled
        table = ScalarTable(self._entities.times(np.array(times)))
        table.add_rows(f"{self._entities.root}/bus/load", np.concatenate(
            (measured, np.broadcast_to(estimates[None, :, None], (len(rows), len(estimates), 1))),
            axis=2).reshape(len(rows), -1))
        table.send(self._entities.recording)
