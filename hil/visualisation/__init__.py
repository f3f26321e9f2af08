"""Visualisation: a run's control samples, drive states and bus load, logged to rerun."""

from hil.visualisation.columns import SimTimeMap
from hil.visualisation.recorder import BenchParts, RunRecorder

__all__ = ["BenchParts", "RunRecorder", "SimTimeMap"]
