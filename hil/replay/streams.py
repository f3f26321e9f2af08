"""The drives' answers, the log's and the replay's, sorted into streams (one per drive and
CAN id, paired in order) and timed states (a heartbeat's, on the drive's own clock), each
pair handed to the judge as it is whole; the sensors' frames likewise, compared byte for
byte.

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
        """A replayed drive's or sensor's frame on ``bus``, after a master frame logged at
        ``cause``."""
        what = self._tellers[bus].sensor(sent)
        if what is not None:
            self._replayed_sensor(bus, cause, sent, what, cycle, now)
            return
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

    def logged_sensor(self, logged: LoggedFrame) -> None:
        """A sensor's frame of the log: compared byte for byte with the replay's in a
        lock-step log (its samples fall on the plant's time, which the replay repeats); a
        real-time log's follow the plant's exact state, which no replay repeats, and hil has
        no tolerance for them (hil's choice: counted, said, not compared)."""
        what = self._tellers[logged.bus].sensor(logged.frame)
        if what is None or what.endswith("boot-up"):     # at power-on, before any master
            return
        if self._report.clock != "cycles":
            self._report.sensor_frames_unchecked += 1
            return
        stream = self._sensor_stream(logged.bus, logged.frame, what)
        stream.logged.append(Answer(logged.frame, 0, 0.0, logged.number))
        self._compare_bytes(stream)

    def _replayed_sensor(self, bus: int, cause: float, sent: Frame, what: str, cycle: int,
                         now: float) -> None:
        last = self._survey.last_sensor_time[bus]
        if what.endswith("boot-up") or self._report.clock != "cycles":
            return
        if last is None or cause > last:
            self._report.after_the_log += 1
            return
        stream = self._sensor_stream(bus, sent, what)
        stream.replayed.append(Answer(sent, cycle, now))
        self._compare_bytes(stream)

    def _compare_bytes(self, stream: AnswerStream) -> None:
        for logged, replayed in stream.pairs():
            self._report.sensor_frames += 1
            if logged.frame.data != replayed.frame.data:
                self._judge.diverged(stream.divergence(logged, replayed, "bytes",
                                                       logged.frame.data.hex(" "),
                                                       replayed.frame.data.hex(" ")))

    def _sensor_stream(self, bus: int, frame: Frame, what: str) -> AnswerStream:
        key = (bus, -1, frame.identifier, frame.extended)
        stream = self._streams.get(key)
        if stream is None:
            device, _, name = what.rpartition(" ")
            stream = self._streams[key] = AnswerStream(self._bus_names[bus], device,
                                                       frame.identifier, name)
        return stream

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
            stream = self._streams[key] = AnswerStream(self._bus_names[bus], drive_config.label,
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
