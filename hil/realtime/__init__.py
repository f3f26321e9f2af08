"""Real-time loops on a stock kernel: scheduling (:mod:`~hil.realtime.scheduling`), pacing
(:mod:`~hil.realtime.pacing`), what they achieved (:mod:`~hil.realtime.statistics`), the
clock a run keeps (:mod:`~hil.realtime.timing`), the garbage collector around them
(:mod:`~hil.realtime.collector`) and the work they hand to a thread of its own
(:mod:`~hil.realtime.side_work`)."""

from hil.realtime.collector import paused_collection, release_gradually
from hil.realtime.pacing import CyclePacer
from hil.realtime.scheduling import (
    IO_PRIORITY, REAL_TIME_PRIORITY, SIDE_PRIORITY, enter_background, enter_real_time,
    enter_side_work, leave_background, lock_step_cpus, real_time_cpus, use_fifo,
)
from hil.realtime.side_work import SideWorkQueue
from hil.realtime.statistics import PeriodStatistics, Ring
from hil.realtime.timing import LOCK_STEP, REAL_TIME, Timing

__all__ = ["IO_PRIORITY", "LOCK_STEP", "REAL_TIME", "REAL_TIME_PRIORITY", "SIDE_PRIORITY",
           "CyclePacer", "PeriodStatistics", "Ring", "SideWorkQueue", "Timing",
           "enter_background", "enter_real_time", "enter_side_work", "leave_background",
           "lock_step_cpus", "paused_collection", "real_time_cpus", "release_gradually",
           "use_fifo"]
