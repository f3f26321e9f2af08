"""What real-time loops achieved: each cycle's period and busy time, and the rings that keep
the latest values of a series for percentiles."""

from __future__ import annotations

import math

import numpy as np


class Ring:
    """The latest ``keep`` values of a series, in a buffer allocated and written once at the
    start (a long run neither grows nor shows growth in its memory figures), with the count
    over the whole run."""

    def __init__(self, keep: int):
        # np.full writes every page now: the memory is taken here, not value by value
        self._values = np.full(keep, np.nan)
        self.count = 0

    @property
    def keep(self) -> int:
        return len(self._values)

    def add(self, value: float) -> None:
        self._values[self.count % len(self._values)] = value
        self.count += 1

    def clear(self) -> None:
        self.count = 0

    @property
    def values(self) -> np.ndarray:
        """The values kept, oldest first."""
        ring = self._values
        if self.count <= len(ring):
            return ring[:self.count].copy()
        oldest = self.count % len(ring)
        return np.concatenate((ring[oldest:], ring[:oldest]))

    def percentiles_us(self, name: str) -> dict:
        """p50, p99 and max of the values kept (s), in us, named ``<name>_p50_us`` etc."""
        values = self.values * 1e6
        if not len(values):
            return {}
        return {f"{name}_p50_us": float(np.percentile(values, 50)),
                f"{name}_p99_us": float(np.percentile(values, 99)),
                f"{name}_max_us": float(values.max())}


class PeriodStatistics:
    """Real-time mode, in seconds: each cycle's period (from its release, when its frames
    start out, to the next release) and busy time (release to the end of its work). Counts
    over the whole run; the latest ``keep`` cycles for percentiles (:class:`Ring`). A cycle
    is missed when its period is over 1.5 nominal ones."""

    KEEP = 100_000

    def __init__(self, nominal: float, keep: int = KEEP):
        self.nominal = nominal
        self._periods = Ring(keep)
        self._busy = Ring(keep)
        self.missed = 0
        self.scheduling = "not started"    # what the loop's thread runs under (CyclePacer)
        #: the busy-waited end of each wait now (s; CyclePacer)
        self.spin = math.nan

    @property
    def count(self) -> int:
        return self._periods.count

    def add(self, period: float, busy: float) -> None:
        self._periods.add(period)
        self._busy.add(busy)
        self.missed += period > 1.5 * self.nominal

    def clear(self) -> None:
        """Forget the cycles so far (a measurement starts here)."""
        self._periods.clear()
        self._busy.clear()
        self.missed = 0

    @property
    def samples(self) -> np.ndarray:
        """The periods kept, oldest first."""
        return self._periods.values

    @property
    def busy(self) -> np.ndarray:
        """The busy times kept, oldest first."""
        return self._busy.values

    def figures(self) -> dict:
        """The cycles kept: period mean, |period - nominal| and busy percentiles (us), with
        the counts over the whole run and the scheduling. Needs at least one cycle."""
        periods = self.samples
        errors = np.abs(periods - self.nominal) * 1e6
        busy = self.busy * 1e6
        return {"cycles": self.count, "period_mean_ms": float(periods.mean() * 1e3),
                "error_p50_us": float(np.percentile(errors, 50)),
                "error_p99_us": float(np.percentile(errors, 99)),
                "error_max_us": float(errors.max()), "missed": self.missed,
                "busy_p50_us": float(np.percentile(busy, 50)),
                "busy_p99_us": float(np.percentile(busy, 99)), "busy_max_us": float(busy.max()),
                "scheduling": self.scheduling, "spin_us": self.spin * 1e6}

    def summary(self) -> str:
        if not self.count:
            return f"{self.scheduling}; no cycles"
        f = self.figures()
        kept = self._periods.keep
        latest = "" if self.count <= kept else f" (the latest {kept})"
        spin = f", spin {self.spin * 1e6:.0f} us" if math.isfinite(self.spin) else ""
        return (f"{self.scheduling}{spin}; {self.count} cycles, missed {self.missed}; period "
                f"mean{latest} {f['period_mean_ms']:.3f} ms, |error| p50 {f['error_p50_us']:.0f} "
                f"us, p99 {f['error_p99_us']:.0f} us, max {f['error_max_us']:.0f} us; busy p50 "
                f"{f['busy_p50_us']:.0f} us, p99 {f['busy_p99_us']:.0f} us")
