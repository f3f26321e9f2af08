"""Visualisation: a run's control samples, drive states and bus load, logged to rerun."""

from hil.visualisation.recorder import RunRecorder, SimTimeMap

__all__ = ["RunRecorder", "SimTimeMap"]
