"""The visualiser process' loop: Zenoh in, rerun out.

Zenoh callbacks only queue what arrives; one thread does all rerun logging,
so batches are logged in arrival order and none is dropped. Each batch's
lag (logged time minus its newest cycle's wall time) is kept for the summary.
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
from hil.messaging.zenoh_api import RunSubscriber, key
from hil.realtime.stalls import Stall
from hil.visualisation.recorder import RunRecorder


class VizNode:
    """Logs a robot's run (control samples, sim clock, diagnostics, bus load) until
    :meth:`stop`."""

    def __init__(self, recorder: RunRecorder, session: zenoh.Session, robot: str,
                 monitor: BusMonitor | None = None, bus_load_hz: float = 10.0):
        self.recorder = recorder
        self.monitor = monitor
        self.batches = 0
        self.lags: list[float] = []
        self.processing: list[float] = []
        self._session, self._robot = session, robot
        self._period = 1.0 / bus_load_hz
        self._queue: queue.SimpleQueue = queue.SimpleQueue()
        self._stop = threading.Event()
        self._errors = 0
        self.subscriber = RunSubscriber(session, robot, self._queue.put,
                                        lambda wall, sim: self._queue.put((wall, sim)),
                                        self._report, self._queue.put, self._queue.put)

    def _report(self, text: str) -> None:
        self._errors += 1
        if self._errors == 1 or self._errors % 100 == 0:
            print(f"hil viz: {text} ({self._errors} so far)", file=sys.stderr, flush=True)

    def stop(self) -> None:
        self._stop.set()

    def run(self) -> None:
        """Log until stopped, then log what is still queued."""
        token = self._session.liveliness().declare_token(key(self._robot, "viz"))
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
                    self.recorder.log_bus_load(now, self.monitor.meter.take(now))
        finally:
            token.undeclare()
            self.subscriber.close()
            while True:
                try:
                    self._handle(self._queue.get_nowait())
                except queue.Empty:
                    break

    def _handle(self, item) -> None:
        if isinstance(item, ControlSamples):
            started = time.perf_counter()
            self.recorder.log_samples(item)
            self.processing.append(time.perf_counter() - started)
            self.lags.append(time.time() - item.wall_time[-1])
            self.batches += 1
        elif isinstance(item, DiagnosticStatus):
            self.recorder.log_diagnostic(item)
        elif isinstance(item, Stall):
            self.recorder.log_stall(item)
        else:
            self.recorder.log_clock(*item)

    def summary(self) -> str:
        text = (f"{self.recorder.cycles_logged} cycles in {self.batches} batches, "
                f"{self.recorder.cycles_lost} lost, {self.recorder.stalls_logged} stalls")
        if self.lags:
            lags = np.array(self.lags) * 1e3
            text += (f"; lag p50 {np.percentile(lags, 50):.1f} ms, p99 "
                     f"{np.percentile(lags, 99):.1f} ms, max {lags.max():.1f} ms; logging "
                     f"{np.mean(self.processing) * 1e3:.2f} ms per batch")
        if self._errors:
            text += f"; {self._errors} malformed payloads dropped"
        return text
