"""Visualisation: a run's control samples, drive states and bus load, logged to rerun.

rerun is imported with the recorder's names, on their first use: ``hil up`` reads the
segment names (:mod:`hil.visualisation.segments`) without loading rerun, which took 11 of
its 21 s of start-up on a 2-vCPU host like CI's (2026-11-29)."""

from hil.lazy import lazy_exports

__all__ = ["BenchParts", "RunRecorder", "SimTimeMap"]
__getattr__ = lazy_exports(__name__, {"BenchParts": "hil.visualisation.recorder",
                                      "RunRecorder": "hil.visualisation.recorder",
                                      "SimTimeMap": "hil.visualisation.columns"})
