"""The visualiser process' loop: Zenoh in, rerun out, for one robot or several.

Zenoh callbacks only queue what arrives (with the recorder of its robot); one thread does
all rerun logging, so batches are logged in arrival order and none is dropped. Each
batch's lag (logged time minus its newest cycle's wall time) is kept for the summary.
"""

from __future__ import annotations

import queue
import sys
import threading
import time

import numpy as np
import zenoh

from hil.can.monitor import BusMonitor
from hil.messaging.diagnostics import DiagnosticStatus
from hil.messaging.samples import ControlSamples
from hil.messaging.scene import SceneState
from hil.messaging.zenoh_api import RunSubscriber, key
from hil.realtime.stalls import Stall
from hil.visualisation.recorder import RunRecorder


class VizNode:
    """Logs robots' runs (control samples, sim clock, diagnostics, bus load), each with its
    recorder, until :meth:`stop`. The monitor's buses are named as the recorders'
    ``monitor_names``."""

    def __init__(self, recorders: list[RunRecorder], session: zenoh.Session,
                 monitor: BusMonitor | None = None, bus_load_hz: float = 10.0):
        self.recorders = recorders
        self.monitor = monitor
        self.batches = 0
        self.lags: list[float] = []
        self.processing: list[float] = []
        self._session = session
        self._period = 1.0 / bus_load_hz
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._stop = threading.Event()
        self._errors = 0
        self.subscribers = [self._subscribe(recorder) for recorder in recorders]

    def _subscribe(self, recorder: RunRecorder) -> RunSubscriber:
        def put(item) -> None:
            self._queue.put((recorder, item))

        return RunSubscriber(self._session, recorder.robot.name, put,
                             lambda wall, sim: put((wall, sim)), self._report, put, put, put)

    def _report(self, text: str) -> None:
        self._errors += 1
        if self._errors == 1 or self._errors % 100 == 0:
            print(f"hil viz: {text} ({self._errors} so far)", file=sys.stderr, flush=True)

    def stop(self) -> None:
        self._stop.set()

    def run(self) -> None:
        """Log until stopped, then log what is still queued."""
        tokens = [self._session.liveliness().declare_token(key(r.robot.name, "viz"))
                  for r in self.recorders]
        next_load = time.monotonic() + self._period
        try:
            while not self._stop.is_set():
                try:
                    self._handle(self._queue.get(timeout=self._period / 2))
                except queue.Empty:
                    pass
                if self.monitor is not None and time.monotonic() >= next_load:
                    next_load += self._period
                    now = time.time()
                    loads = self.monitor.meter.take(now)
                    for recorder in self.recorders:
                        recorder.log_bus_load(now, loads)
        finally:
            for token in tokens:
                token.undeclare()
            for subscriber in self.subscribers:
                subscriber.close()
            while True:
                try:
                    self._handle(self._queue.get_nowait())
                except queue.Empty:
                    break

    def _handle(self, queued: tuple[RunRecorder, object]) -> None:
        recorder, item = queued
        if isinstance(item, ControlSamples):
            started = time.perf_counter()
            recorder.log_samples(item)
            self.processing.append(time.perf_counter() - started)
            self.lags.append(time.time() - item.wall_time[-1])
            self.batches += 1
        elif isinstance(item, DiagnosticStatus):
            recorder.log_diagnostic(item)
        elif isinstance(item, Stall):
            recorder.log_stall(item)
        elif isinstance(item, SceneState):
            recorder.log_scene(item)
        else:
            recorder.log_clock(*item)

    def summary(self) -> str:
        recorders = self.recorders
        text = (f"{sum(r.cycles_logged for r in recorders)} cycles in {self.batches} batches, "
                f"{sum(r.cycles_lost for r in recorders)} lost, "
                f"{sum(r.stalls_logged for r in recorders)} stalls")
        if len(recorders) > 1:
            text += " (" + ", ".join(f"{r.robot.name} {r.cycles_logged} cycles, {r.cycles_lost} "
                                     f"lost" for r in recorders) + ")"
        if self.lags:
            lags = np.array(self.lags) * 1e3
            text += (f"; lag p50 {np.percentile(lags, 50):.1f} ms, p99 "
                     f"{np.percentile(lags, 99):.1f} ms, max {lags.max():.1f} ms; logging "
                     f"{np.mean(self.processing) * 1e3:.2f} ms per batch")
        if self._errors:
            text += f"; {self._errors} malformed payloads dropped"
        return text
