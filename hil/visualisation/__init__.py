"""Visualisation: a run's control samples, drive states and bus load, logged to rerun."""

from hil.visualisation.recorder import BenchParts, RunRecorder, SimTimeMap

__all__ = ["BenchParts", "RunRecorder", "SimTimeMap"]
