"""Replay: a CAN log as a regression test, and a measure of how close the bench is to the
robot the log came from.

``hil replay LOG CONFIG`` feeds the frames the master sent (:mod:`.log` tells them from the
drives' by the protocols' ids) to the simulated drives of CONFIG and compares every answer
with the log's (:mod:`.compare`), closed loop on the drives' side (:mod:`.replay`). A layer
beside the bench: it runs the simulator, never a master.
"""

from __future__ import annotations

from hil.replay.compare import Divergence, JointStatistics, Tolerances
from hil.replay.files import not_whole
from hil.replay.log import (
    REORDER_WINDOW, LoggedFrame, Survey, frames, parse_channels, survey,
)
from hil.replay.replay import Replay
from hil.replay.report import Report

#: a log whose master cycled in the config's period this much of its time is a real-time
#: run's or a robot's (a controller may cycle faster while it brings drives up); a lock-step
#: run's cycles come as fast as the host computes them, a few percent of them in period
REAL_TIME_SHARE = 0.5
#: the default tolerances of a replay on the log's clock (drive units: counts, counts/s,
#: per mille of the rated torque); a lock-step replay's are 0 (bit for bit)
LOG_CLOCK_TOLERANCES = {"position": 8.0, "velocity": 2048.0, "torque": 100.0}


def log_clock(found: Survey) -> str:
    """``log`` for a log whose master kept the config's period (a real-time run's, a
    robot's), else ``cycles`` (a lock-step run's)."""
    return "log" if found.in_period > REAL_TIME_SHARE else "cycles"


__all__ = ["Divergence", "JointStatistics", "REAL_TIME_SHARE", "LOG_CLOCK_TOLERANCES",
           "REORDER_WINDOW", "LoggedFrame", "Replay", "Report", "Survey", "Tolerances", "frames",
           "log_clock", "not_whole", "parse_channels", "survey"]
