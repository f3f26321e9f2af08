"""Work a real-time process hands to a thread of its own (encoding a recording's batch,
putting a log line): handed over without blocking, done below the process' frame handling."""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable
from typing import Generic, TypeVar

from hil.realtime.scheduling import enter_side_work

Item = TypeVar("Item")


class SideWorkQueue(Generic[Item]):
    """Items put from any thread (a real-time loop's too: :meth:`put` never blocks) and
    handled in turn by ``handle`` in a thread of its own at the side-work priority
    (:func:`enter_side_work`). Past ``backlog`` waiting items the newest are dropped and
    counted in :attr:`dropped`."""

    def __init__(self, handle: Callable[[Item], None], backlog: int, name: str):
        self._handle = handle
        self.dropped = 0
        self._queue: queue.Queue[Item | None] = queue.Queue(backlog)
        self._thread = threading.Thread(target=self._work, name=name, daemon=True)
        self._thread.start()

    def put(self, item: Item) -> None:
        try:
            self._queue.put_nowait(item)
        except queue.Full:
            self.dropped += 1

    def _work(self) -> None:
        enter_side_work()
        while (item := self._queue.get()) is not None:
            self._handle(item)

    def close(self, timeout: float) -> None:
        """Handle what is queued (for up to ``timeout`` s), then stop."""
        self._queue.put(None)
        self._thread.join(timeout)
