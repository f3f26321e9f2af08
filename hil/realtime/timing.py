"""How a run keeps time: the one choice the simulator, the control loop, the stack, the
bench and the commands are handed (``--real-time``, ``--lock-step``)."""

from __future__ import annotations

import enum


class Timing(enum.Enum):
    """The clock a run keeps."""

    #: on the wall clock: the controller paces each cycle, the plant follows real time
    REAL_TIME = "real-time"
    #: one control period per cycle: the plant advances a period per SYNC, however fast the
    #: processes go (reproducible bit for bit, and blind to the host's stalls)
    LOCK_STEP = "lock-step"

    @property
    def lock_step(self) -> bool:
        return self is Timing.LOCK_STEP

    def __str__(self) -> str:
        return self.value


REAL_TIME, LOCK_STEP = Timing.REAL_TIME, Timing.LOCK_STEP
