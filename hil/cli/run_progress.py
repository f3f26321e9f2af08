"""What ``hil up`` shows and judges of a running robot: the recorded cycles, the
controller's diagnostics and the bench's stalls, as they come."""

from __future__ import annotations

import math
import sys
import threading
import time
from collections.abc import Callable

import numpy as np

from hil.messaging.diagnostics import DiagnosticStatus
from hil.messaging.samples import ControlSamples
from hil.messaging.scene import SceneState
from hil.realtime.stalls import Stall, StallTally


#: a floating base that comes down below this share of the height it started at has fallen
#: (hil's bound: a standing robot's base sags millimetres under its joints' loops; a
#: humanoid or quadruped lying on the floor has its base at a fifth of it or less)
FALLEN_SHARE = 0.6


class Progress:
    """Follows the run: the recorded cycles (how many, the largest tracking error, in real
    time the control loop's missed cycles and round trips) and the controller's
    diagnostics, printed as they come."""

    def __init__(self, max_stalls: int | None = None,
                 on_too_many: Callable[[], None] = lambda: None, label: str = ""):
        """``label``: before what is printed of this robot ("ur3: " where a run has several)."""
        self.lock = threading.Lock()
        self.label = label
        self.diagnostics: list[DiagnosticStatus] = []
        #: malformed payloads, as RunSubscriber words them
        self.problems: list[str] = []
        self.cycles = 0
        self.control_time = 0.0
        self.positions: np.ndarray | None = None
        self.joint_names: tuple[str, ...] = ()
        self.worst = (0.0, "")
        self._cycles_shown = 0
        self.missed = 0                 # cycles whose period was over 1.5 nominal ones
        self._round_trips: list[np.ndarray] = []      # since the last line
        #: the stalls the real-time processes reported (real time) since :meth:`count_stalls`,
        #: per process
        self.stalls = StallTally()
        self._counting_since = math.inf
        #: the stall past ``max_stalls``, on which ``on_too_many`` was called
        self.too_many: Stall | None = None
        self._max_stalls, self._on_too_many = max_stalls, on_too_many
        #: each joint's fastest speed in the samples since :meth:`take_fastest` (None: none)
        self._fastest: np.ndarray | None = None
        #: a floating base's height (m) when first seen, and its lowest since (None: none seen)
        self._base_heights: tuple[float, float] | None = None

    def on_samples(self, batch: ControlSamples) -> None:
        errors = np.abs(batch.reference - batch.position).max(axis=0)
        with self.lock:
            self.missed += int(np.sum(batch.cycle_period > 1.5 * batch.period))
            self._round_trips.append(batch.round_trip)
            self.cycles += len(batch)
            self.control_time = float(batch.control_time[-1])
            self.positions, self.joint_names = batch.position[-1], batch.joint_names
            fastest = np.abs(batch.velocity).max(axis=0)
            self._fastest = fastest if self._fastest is None else np.maximum(self._fastest,
                                                                             fastest)
            if len(errors) and errors.max() > self.worst[0]:
                self.worst = (float(errors.max()), batch.joint_names[int(errors.argmax())])

    def count_stalls(self) -> None:
        """From now on count the stalls: ``hil up`` calls it as it releases the controllers
        (the bring-up's stalls are counted, the start-up's before it are not the run's)."""
        with self.lock:
            self._counting_since = time.time()

    def on_stall(self, stall: Stall) -> None:
        with self.lock:
            if stall.end < self._counting_since:
                return
            self.stalls.add(stall)
            if (self._max_stalls is None or self.too_many is not None
                    or self.stalls.total <= self._max_stalls):
                return
            self.too_many = stall
        self._on_too_many()

    def on_diagnostic(self, diagnostic: DiagnosticStatus) -> None:
        with self.lock:
            self.diagnostics.append(diagnostic)
        print(f"hil up: {self.label}control: {diagnostic.level}: {diagnostic.message}",
              file=sys.stderr, flush=True)

    def take_fastest(self) -> dict[str, float] | None:
        """Each joint's fastest speed (rad/s or m/s) in every cycle heard since the last call,
        by name; None where none was heard since."""
        with self.lock:
            fastest, self._fastest = self._fastest, None
            names = self.joint_names
        return None if fastest is None else dict(zip(names, fastest.tolist()))

    def on_scene(self, scene: SceneState) -> None:
        if scene.base is None:
            return
        height = float(scene.base[0][2])
        with self.lock:
            start, lowest = self._base_heights or (height, height)
            self._base_heights = (start, min(lowest, height))

    def fallen(self) -> str | None:
        """How a floating base fell (came down below FALLEN_SHARE of its first height), or
        None: it did not, or the robot has none."""
        with self.lock:
            if self._base_heights is None:
                return None
            start, lowest = self._base_heights
        if lowest >= FALLEN_SHARE * start:
            return None
        return f"the robot fell: its base came down from {start:.3f} m to {lowest:.3f} m"

    def faults(self) -> int:
        """How many faults (ERROR diagnostics) the controller reported."""
        with self.lock:
            return sum(d.level == "ERROR" for d in self.diagnostics)

    def explained(self) -> int:
        """How many of them the controller put down to the bench's own stalls."""
        with self.lock:
            return sum(int(dict(d.values).get("explains", 0)) for d in self.diagnostics
                       if dict(d.values).get("kind") == "bench_stall")

    def line(self) -> str:
        with self.lock:
            worst, self.worst = self.worst, (0.0, "")
            fresh, self._cycles_shown = self.cycles > self._cycles_shown, self.cycles
            trips, self._round_trips = self._round_trips, []
            if not fresh:
                return f"cycles {self.cycles:>7}   (no new cycles recorded since the last line)"
            line = (f"cycles {self.cycles:>7}   largest tracking error {worst[0]:.4f} "
                    f"({worst[1] or '-'})")
            trips = np.concatenate(trips) * 1e3 if trips else np.zeros(0)
            if np.isfinite(trips).any():        # real time: the loop's own figures
                late = np.count_nonzero(np.isnan(trips))
                line += (f"   missed {self.missed}   round trip p50 "
                         f"{np.nanpercentile(trips, 50):.2f} ms, max {np.nanmax(trips):.2f} ms"
                         + (f", {late} late" if late else ""))
            return line
