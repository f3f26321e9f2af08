"""The visualiser process' loop: Zenoh in, rerun out, for one robot or several.

Zenoh callbacks only queue what arrives (with the recorder of its robot); one thread does
all rerun logging, so batches are logged in arrival order and none is dropped. Each
batch's lag (logged time minus its newest cycle's wall time) is kept, the last hour's in a
ring allocated once (a soak's memory stays flat), for the summary and the status lines.
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
from hil.messaging.sensors import ImuMessage, WrenchMessage
from hil.messaging.zenoh_api import RunSubscriber, key
from hil.realtime import Ring
from hil.realtime.stalls import Stall
from hil.visualisation.recorder import RunRecorder

#: batches whose lag and logging time are kept: an hour's at 10 batches a second
KEEP = 36_000
#: once stopped, it logs until nothing has come for this long (s)...
QUIET = 0.25
#: ... or for this long at most (s): a sender still running (a visualiser stopped alone)
#: never goes quiet
DRAIN_LIMIT = 3.0


class VizNode:
    """Logs robots' runs (control samples, sim clock, diagnostics, bus load), each with its
    recorder, until :meth:`stop`. The monitor's buses are named as the recorders'
    ``monitor_names``."""

    def __init__(self, recorders: list[RunRecorder], session: zenoh.Session,
                 monitor: BusMonitor | None = None, after_batch=lambda: None,
                 bus_load_hz: float = 10.0, status_period: float = 0.0):
        """``after_batch`` is called after each batch is logged (a file in segments rolls
        over there); every ``status_period`` s (0: never) a status line is printed."""
        self.recorders = recorders
        self.monitor = monitor
        self.batches = 0
        self.lags = Ring(KEEP)
        self.processing = Ring(KEEP)
        self._after_batch = after_batch
        self._status_period = status_period
        self._session = session
        self._period = 1.0 / bus_load_hz
        # not a SimpleQueue: on CPython 3.11 its get(timeout) waits for the next item, with no
        # timeout, once a signal's handler has outlasted the timeout (its loop turns the time
        # left negative, which means forever); a SIGTERM's then never ended a visualiser whose
        # senders were gone (a CI run, hil up SIGKILLed). Queue waits on threading's lock,
        # which ends a wait whose time ran out in a handler
        self._queue: queue.Queue = queue.Queue()
        self._stop = threading.Event()
        self.subscribers = [self._subscribe(recorder) for recorder in recorders]

    def _subscribe(self, recorder: RunRecorder) -> RunSubscriber:
        def put(item) -> None:
            self._queue.put((recorder, item))

        return RunSubscriber(self._session, recorder.robot.name, put,
                             lambda wall, sim: put((wall, sim)), self._report, put, put, put,
                             put, put)

    @staticmethod
    def _report(text: str) -> None:
        # RunSubscriber tells the first malformed payload and every thousandth
        print(f"hil viz: {text}", file=sys.stderr, flush=True)

    def stop(self) -> None:
        self._stop.set()

    def run(self) -> None:
        """Log until stopped, then log what is still queued."""
        tokens = [self._session.liveliness().declare_token(key(r.robot.name, "viz"))
                  for r in self.recorders]
        next_load = time.monotonic() + self._period
        started = next_status = time.monotonic()
        counted = 0                               # batches at the last status line
        try:
            while not self._stop.is_set():
                try:
                    self._handle(self._queue.get(timeout=self._period / 2))
                except queue.Empty:
                    pass
                if self._status_period and time.monotonic() >= next_status + self._status_period:
                    next_status += self._status_period
                    print(f"hil viz: [{next_status - started:7.0f} s] "
                          f"{self._status(self.batches - counted)}", flush=True)
                    counted = self.batches
                if self.monitor is not None and time.monotonic() >= next_load:
                    next_load += self._period
                    self._log_bus_load(time.time() - self.monitor.meter.lag)
        finally:
            self._drain()
            for token in tokens:
                token.undeclare()
            for subscriber in self.subscribers:
                subscriber.close()
            while True:
                try:
                    self._handle(self._queue.get_nowait())
                except queue.Empty:
                    break
            if self.monitor is not None:     # every frame heard: the last row, up to now
                self._log_bus_load(time.time())

    def _log_bus_load(self, until: float) -> None:
        """Each bus' load since the last row, to ``until`` (the wall clock's s)."""
        loads = self.monitor.meter.take(until)
        for recorder in self.recorders:
            recorder.log_bus_load(until, loads)

    def _drain(self) -> None:
        """Once stopped: log what is still on its way (a visualiser behind its senders holds
        their last batches and frames in its links) until nothing has come for QUIET s, at
        most DRAIN_LIMIT s. ``hil up`` stops it after the controllers, whose last frames
        it so records (a lock-step controller closes once the visualiser has heard them)."""
        deadline = time.monotonic() + DRAIN_LIMIT
        heard, quiet_since = self._frames_received(), time.monotonic()
        while time.monotonic() < deadline and time.monotonic() - quiet_since < QUIET:
            try:
                self._handle(self._queue.get(timeout=QUIET / 10))
                quiet_since = time.monotonic()
            except queue.Empty:
                received = self._frames_received()
                if received != heard:
                    heard, quiet_since = received, time.monotonic()

    def _frames_received(self) -> int:
        return self.monitor.received() if self.monitor is not None else 0

    def _handle(self, queued: tuple[RunRecorder, object]) -> None:
        recorder, item = queued
        if isinstance(item, ControlSamples):
            started = time.perf_counter()
            recorder.log_samples(item)
            self.processing.add(time.perf_counter() - started)
            self.lags.add(time.time() - item.wall_time[-1])
            self.batches += 1
            self._after_batch()
        elif isinstance(item, DiagnosticStatus):
            recorder.log_diagnostic(item)
        elif isinstance(item, Stall):
            recorder.log_stall(item)
        elif isinstance(item, SceneState):
            recorder.log_scene(item)
        elif isinstance(item, (ImuMessage, WrenchMessage)):
            recorder.log_sensor(item)
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
        text += self._lag_words(self.lags.values, self.processing.values)
        malformed = sum(subscriber.malformed.count for subscriber in self.subscribers)
        if malformed:
            text += f"; {malformed} malformed payloads dropped"
        return text

    def _status(self, recent: int) -> str:
        """A status line: cycles and losses so far, and the lag of the last ``recent``
        batches."""
        recorders = self.recorders
        lags = self.lags.values[-recent:] if recent else self.lags.values[:0]
        spent = self.processing.values[-recent:] if recent else self.processing.values[:0]
        return (f"{sum(r.cycles_logged for r in recorders)} cycles, "
                f"{sum(r.cycles_lost for r in recorders)} lost; {recent} batches"
                + self._lag_words(lags, spent))

    @staticmethod
    def _lag_words(lags: np.ndarray, spent: np.ndarray) -> str:
        if not len(lags):
            return ""
        lags = lags * 1e3
        return (f"; lag p50 {np.percentile(lags, 50):.1f} ms, p99 "
                f"{np.percentile(lags, 99):.1f} ms, max {lags.max():.1f} ms; logging "
                f"{np.mean(spent) * 1e3:.2f} ms per batch")
