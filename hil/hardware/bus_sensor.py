"""What the controller's side of every CAN sensor shares: its frames taken off its bus'
router as they come (in the router's thread), its samples queued for the control loop, which
takes them at its next cycle."""

from __future__ import annotations

from collections import deque
from typing import Generic, TypeVar

from hil.can.frame import Frame
from hil.can.router import FrameRouter

#: samples kept for the loop: a second's of a sensor at 256 Hz (a loop that stops reading
#: loses the oldest, never grows memory)
KEEP = 256
State = TypeVar("State")


class BusSensor(Generic[State]):
    """A sensor whose frames of ``identifiers`` come to :meth:`on_frame` once
    :meth:`attach` ed; what that queues with :meth:`arrived` the loop :meth:`poll` s."""

    def __init__(self, identifiers: tuple[int, ...], requests: tuple[Frame, ...] = (),
                 every: int = 1):
        """``requests``: the frames that ask a sensor which answers requests only for a
        sample, sent every ``every`` control cycles (a sensor that streams has none)."""
        self.identifiers = identifiers
        self.requests = requests
        self.every = every
        self._queue: deque[State] = deque(maxlen=KEEP)
        self.router: FrameRouter | None = None
        #: why it is not read now (None: it is)
        self.problem: str | None = "its bus is not open yet"

    @property
    def attached(self) -> bool:
        return self.router is not None

    def attach(self, router: FrameRouter) -> None:
        """Listen to its frames on ``router`` (its bus')."""
        self.router = router
        for identifier in self.identifiers:
            router.subscribe(identifier, self.on_frame)
        self.problem = None

    def on_frame(self, frame: Frame) -> None:
        """One of its frames (the router's thread)."""
        raise NotImplementedError

    def request(self, cycle: int) -> None:
        """At control cycle ``cycle``: its requests, on every ``every``-th cycle once
        attached."""
        if self.requests and self.router is not None and cycle % self.every == 0:
            self.router.send_frames(self.requests)

    def arrived(self, state: State) -> None:
        """A sample for the loop."""
        self._queue.append(state)

    def poll(self) -> list[State]:
        """The samples that arrived since the last call."""
        states = []
        while self._queue:
            states.append(self._queue.popleft())
        return states

    def close(self) -> None:
        """Stop listening."""
        if self.router is not None:
            for identifier in self.identifiers:
                self.router.unsubscribe(identifier, self.on_frame)
            self.router = None
        self.problem = "closed"
