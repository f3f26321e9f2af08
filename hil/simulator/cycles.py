"""The cycles a simulated bench runs: counted in real time, each drive's reply sent as the
lock is left; in lock-step, which drives on their bus have had the open cycle's command,
closing it (the plant's steps, then every reply). Either way a bus' replies of one delivery
go in one send."""

from __future__ import annotations

from collections.abc import Callable

from hil.can.frame import Frame
from hil.can.router import FrameRouter
from hil.drives import DriveProfile
from hil.simulator.build import SimulatedBus


class CycleBook:
    """The simulator's cycles; :meth:`commanded` (real time) or :meth:`commanded_in_lock_step`
    is each drive's ``on_command``, called with the simulator's lock held, as is every method
    here."""

    def __init__(self, buses: list[SimulatedBus], drives: list[DriveProfile],
                 step: Callable[[], None], steps_per_cycle: int):
        self.buses = buses
        self._step = step
        self.steps_per_cycle = steps_per_cycle
        #: cycles run: lock-step, the plant's; real time, the most cycle frames (SYNCs,
        #: commands) any drive has had from its master, whoever the master is
        self.cycles = 0
        self._commands: dict[DriveProfile, int] = {}
        self.waiting: set[DriveProfile] = set(drives)   # lock-step: no command yet
        #: the drives on their bus (attached by Simulator.start, until silenced or closed),
        #: kept here: asking each drive (DriveProfile.attached) at every lock-step cycle costs
        #: a call a drive, and this set is the next cycle's waiting set as it is
        self.attached: set[DriveProfile] = set()
        #: real time: the replies taken inside this entry of the lock, by bus
        self._taken: dict[FrameRouter, list[Frame]] = {}

    def leave(self, drive: DriveProfile) -> None:
        """``drive`` has left its bus: no cycle waits for it, no reply of it is sent."""
        self.attached.discard(drive)
        self.waiting.discard(drive)

    def commanded(self, drive: DriveProfile) -> None:
        """Real time: a drive has its command of this cycle, and answers in this entry of
        the lock: its reply taken now, sent as the lock is left (:meth:`send_taken`), with
        the others of its bus taken in the same entry (a master's cycle that came in one
        delivery, over Zenoh) in one send, as lock-step sends them (a profile that sends
        its own, at once)."""
        frames = drive.take_replies()
        router = drive.router
        if frames is None:
            drive.send_replies()
        elif frames and router is not None:
            taken = self._taken.get(router)
            if taken is None:
                self._taken[router] = frames
            else:
                taken += frames
        count = self._commands[drive] = self._commands.get(drive, 0) + 1
        self.cycles = max(self.cycles, count)

    def send_taken(self) -> None:
        """Real time: the replies taken inside the entry of the lock now being left, a bus'
        in one send (the lock's ``leave``)."""
        if self._taken:
            taken, self._taken = self._taken, {}
            for router, frames in taken.items():
                router.send_frames(frames)

    def commanded_in_lock_step(self, drive: DriveProfile) -> None:
        """Lock-step: a drive has its command of this cycle; the last one closes it."""
        self.waiting.discard(drive)
        if not self.waiting:       # else other drives have not had this cycle's command
            self.close()

    def begun(self) -> bool:
        """Lock-step: whether a drive on its bus has had its command of the open cycle."""
        return not self.attached <= self.waiting

    def close(self) -> None:
        """Lock-step: the plant steps one control period, then every drive sends its
        answers."""
        for _ in range(self.steps_per_cycle):
            self._step()
        self.cycles += 1
        self.waiting = set(self.attached)
        self._send_replies()

    def _send_replies(self) -> None:
        """Lock-step: every drive's reply, in config order, those of a bus in one send
        (a profile that sends its own, in its place)."""
        attached = self.attached
        for simulated in self.buses:
            replies: list[Frame] = []
            for drive in simulated.drives:
                frames = drive.take_replies()
                if frames is None:
                    if replies:
                        simulated.router.send_frames(replies)
                        replies = []
                    drive.send_replies()
                elif drive in attached:
                    replies += frames
            if replies:
                simulated.router.send_frames(replies)
