"""Visualisation: a run's control samples, drive states and bus load, logged to rerun.

rerun is imported with the recorder's names, on their first use: ``hil up`` reads the
segment names (:mod:`hil.visualisation.segments`) without loading rerun, whose import
was about half its start-up on a 2-vCPU host like CI's (docs/performance.md,
"2026-12-06, later: figures from code comments")."""

from hil.lazy import lazy_exports

__all__ = ["BenchParts", "RunRecorder", "SimTimeMap"]
__getattr__ = lazy_exports(__name__, {"BenchParts": "hil.visualisation.recorder",
                                      "RunRecorder": "hil.visualisation.recorder",
                                      "SimTimeMap": "hil.visualisation.columns"})
