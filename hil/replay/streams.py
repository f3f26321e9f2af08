"""The drives' answers, the log's and the replay's, sorted into streams (one per drive and
CAN id, paired in order) and timed states (a heartbeat's, on the drive's own clock), each
pair handed to the judge as it is whole.

Drive frames logged before their drive was first addressed are not compared (the drives'
boot-up, the heartbeats before the master came: the caller leaves them out), nor the
replay's answers to master frames logged after the log's last frame from a drive of that
bus (the log ended before they could come). Watchdogs and timed frames run on no clock in a
replay: a drive's timed state (its heartbeat) is sampled after each master frame that
concerns it.
"""

from __future__ import annotations

from hil.bus_config import DriveConfig, SystemConfig
from hil.can.frame import Frame
from hil.drives.profile import DriveProfile
from hil.protocols import Sender
from hil.replay.compare import Answer, AnswerStream, TimedStates
from hil.replay.judge import Judge
from hil.replay.log import BusFrames, LoggedFrame, Survey
from hil.replay.report import Report


class Streams:
    """Every drive's answer streams and timed states of a replay."""

    def __init__(self, config: SystemConfig, survey: Survey,
                 drives: dict[tuple[int, int], tuple[DriveConfig, DriveProfile]],
                 judge: Judge, report: Report):
        self._bus_names = [bus.name for bus in config.buses]
        self._survey = survey
        self._drives = drives
        self._judge = judge
        self._report = report
        self._tellers = [BusFrames(bus) for bus in config.buses]
        #: (bus index, node id, identifier, extended) -> the drive's frames of that id
        self._streams: dict[tuple[int, int, int, bool], AnswerStream] = {}
        self._timed: dict[tuple[int, int, int], TimedStates] = {}

    def replayed(self, bus: int, cause: float, sent: Frame, cycle: int, now: float) -> None:
        """A replayed drive's frame on ``bus``, in answer to a master frame logged at
        ``cause``."""
        source = self._tellers[bus].source(sent)
        if source is None or source.sender is not Sender.DRIVE:
            return
        _, drive = self._drives[bus, source.node_id]
        if drive.timed(sent):
            return           # a heartbeat on the wall clock (canopen's own timer thread)
        stream = self._stream(bus, source.node_id, sent, source.what)
        last = self._survey.last_drive_time[bus]
        if last is None or cause > last:
            self._report.after_the_log += 1
            return
        stream.replayed.append(Answer(sent, cycle, now))
        self._judge.compare(bus, source.node_id, stream)

    def logged(self, logged: LoggedFrame) -> None:
        """A drive's frame of the log."""
        key = (logged.bus, logged.source.node_id)
        _, drive = self._drives[key]
        frame = logged.frame
        if drive.timed(frame):
            if frame.identifier in drive.timed_ids():
                self._timed_states(logged.bus, logged.source.node_id, frame.identifier).log(
                    frame.data, logged.number)
            return
        stream = self._stream(logged.bus, logged.source.node_id, frame, logged.source.what)
        stream.logged.append(Answer(frame, 0, 0.0, logged.number))
        self._judge.compare(logged.bus, logged.source.node_id, stream)

    def sample(self, bus: int, node: int, drive: DriveProfile, cycle: int, now: float) -> None:
        """The replayed drive's timed states, after a master frame that concerns it."""
        for can_id in drive.timed_ids():
            self._timed_states(bus, node, can_id).replay(drive.timed_content(can_id), cycle, now)

    def finish(self) -> None:
        """At the log's end: what one side has and the other lacks, and each drive's timed
        states against the log's."""
        for stream in self._streams.values():
            leftover = stream.leftover()
            if leftover is not None:
                self._judge.diverged(leftover)
        for states in self._timed.values():
            divergence = states.divergence()
            if divergence is None:
                self._report.states_checked += len(states.logged)
            else:
                self._judge.diverged(divergence)

    def _stream(self, bus: int, node: int, frame: Frame, what: str) -> AnswerStream:
        key = (bus, node, frame.identifier, frame.extended)
        stream = self._streams.get(key)
        if stream is None:
            drive_config, _ = self._drives[bus, node]
            stream = self._streams[key] = AnswerStream(self._bus_names[bus], drive_config,
                                                       frame.identifier, what)
        return stream

    def _timed_states(self, bus: int, node: int, can_id: int) -> TimedStates:
        key = (bus, node, can_id)
        states = self._timed.get(key)
        if states is None:
            drive_config, _ = self._drives[bus, node]
            states = self._timed[key] = TimedStates(self._bus_names[bus], drive_config,
                                                    f"heartbeat 0x{can_id:03X}")
        return states
