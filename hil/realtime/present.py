"""The lock of a real-time simulated bench (:class:`hil.simulator.Simulator`'s): entering it
first steps the plant up to the present."""

from __future__ import annotations

import threading
from collections.abc import Callable


class PlantPresent:
    """The lock that drives hold around everything a frame does to them (``DriveProfile.lock``).

    A re-entrant lock over the plant and every drive. Entering it (outermost entry only)
    first calls ``advance``: in real time, the simulator's step of the plant up to the
    present. Leaving it (outermost only) last calls ``leave``, still holding it: the
    simulator's send of the replies taken inside (:meth:`hil.simulator.cycles.CycleBook.
    send_taken`).
    """

    def __init__(self, advance: Callable[[], None], leave: Callable[[], None] | None = None):
        self._lock = threading.RLock()
        self._advance = advance
        self.leave = leave
        self._depth = 0          # entries by the owning thread (changed only under the lock)

    def __enter__(self) -> PlantPresent:
        self._lock.acquire()
        self._depth += 1
        if self._depth == 1:
            try:
                self._advance()
            except BaseException:
                self.__exit__()
                raise
        return self

    def __exit__(self, *exc_info) -> None:
        try:
            if self._depth == 1 and self.leave is not None:
                self.leave()
        finally:
            self._depth -= 1
            self._lock.release()
