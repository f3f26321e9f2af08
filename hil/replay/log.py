"""A CAN log as a replay reads it: each frame on a bus of the bus config, told the master's
or a drive's by its protocol (:meth:`hil.protocols.base.Protocol.frame_source`).

Any format python-can reads here, within bounds (BLF, ASC, candump text, CSV, TRC, MF4
with asammdf: :mod:`hil.replay.files`): hil's own logs, or a candump of a real robot; or a
folder of a log per bus, each named after its bus (``arm.blf``, ``wrist.blf``: what
:meth:`hil.testing.DrivesBench.log_to` and the ``hil_drives`` fixture write; a name too
long for a file's cut, :mod:`hil.file_names`), its files read as one log in time order, each
file's frames on the bus of its name (a BLF stores a channel number only: python-can's
writer puts a channel named without a number on its default, read back as 0, so a bench's
files could not say their bus otherwise). A log's channels are matched to the config's buses
by ``--channel`` (``LOGCHANNEL=BUS``), else by number (BLF and ASC number channels from 1, in
the config's bus order, as ``hil viz`` writes them), else by name (the bus' python-can channel
or its name; a folder's file's), else one channel to a config of one bus.

:func:`survey` reads a log once before anything is replayed and refuses one that does not
fit the config (a node the bus has no drive of, a frame no protocol of the bus knows nor a
sensor of it sends, a channel with no bus) with every misfit, each with its first place in
the log.
"""

from __future__ import annotations

import heapq
import math
import time
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from hil.bus_config import BusConfig, SystemConfig
from hil.can.frame import Frame
from hil.can.messages import frame_of
from hil.errors import ConfigError, UsageError, error
from hil.file_names import file_stem
from hil.protocols import FrameSource, Sender, protocol
from hil.replay.files import read_log

#: misfits listed in a refusal before "and N more"
MISFITS_SHOWN = 8
#: how far out of time order (s) a log's frames are put back in order at least: a monitor
#: that reads each bus' queue in turn (python-can's Notifier, hil viz) writes a burst of one
#: bus before the same moment's frames of another; a log written further out of order (a
#: monitor that fell behind one sender more than another: hil viz paused 1.5 s wrote 1.5 s
#: out of order) is put back in order as far as :func:`survey` measured
REORDER_WINDOW = 1.0
#: the most a log may be written out of time order (s): the frames of that much of the log
#: are held to order them (a lock-step run's 30,000 frames a second: about 270 MB)
MAX_REORDER = 30.0
#: how close to the config's period an interval between cycles is one of a real-time run
PERIOD_TOLERANCE = 0.1


@dataclass(frozen=True)
class LoggedFrame:
    """One frame of a log, placed on a bus and told whose it is (a sensor's: no source; a
    master's request to a sensor: the master's, to no drive)."""

    number: int               # its place in the log, from 1
    time: float               # the log's timestamp (s)
    bus: int                  # index of its bus in the config
    frame: Frame
    source: FrameSource | None


class BusFrames:
    """Tells the frames of one bus of the config: by each of its protocols in turn."""

    def __init__(self, bus: BusConfig):
        self.name = bus.name
        by_protocol: dict[str, dict[int, object]] = {}
        for drive in bus.drives:
            by_protocol.setdefault(drive.protocol, {})[drive.node_id] = drive.options
        self._protocols = [(protocol(name), drives) for name, drives in by_protocol.items()]
        self.node_ids = sorted(d.node_id for d in bus.drives)
        #: (identifier, extended) -> what, of the frames of the bus' sensors
        self._sensors = {(spec.identifier, spec.extended): spec.what
                         for spec in bus.sensor_frames}
        #: (identifier, extended, remote) -> its source, for the frames whose bytes do not
        #: matter
        self._known: dict[tuple[int, bool, bool], FrameSource | None] = {}

    def sensor(self, frame: Frame) -> str | None:
        """What a sensor's frame is ("sensor 'imu' TPDO1"); None for another."""
        return self._sensors.get((frame.identifier, frame.extended))

    def source(self, frame: Frame) -> FrameSource | None:
        key = (frame.identifier, frame.extended, frame.remote)
        if key in self._known:
            return self._known[key]
        found = self._told(frame)
        if not any(spec.source_reads_data(frame, drives) for spec, drives in self._protocols):
            self._known[key] = found
        return found

    def _told(self, frame: Frame) -> FrameSource | None:
        for spec, drives in self._protocols:
            try:
                found = spec.frame_source(frame, drives)
            except NotImplementedError as exc:
                raise ConfigError.single(f"bus '{self.name}': {exc}; it cannot be replayed") \
                    from None
            if found is not None:
                return found
        return None


@dataclass
class Survey:
    """What a whole log holds, per bus of the config."""

    path: Path
    channels: dict[object, int]          # the log's channel -> bus index
    frames: int = 0
    first_time: float | None = None
    last_time: float | None = None
    #: per bus and node (None: all): the master's frames that start a cycle (SYNCs, cyclic
    #: requests)
    cycle_frames: list[dict[int | None, int]] = field(default_factory=list)
    #: per bus: the time of the log's last frame from a drive (None: none)
    last_drive_time: list[float | None] = field(default_factory=list)
    #: per bus: the time of the log's last frame from a sensor (None: none)
    last_sensor_time: list[float | None] = field(default_factory=list)
    #: per bus and node (None: to all of the bus), when the master first sent to it
    first_master_times: dict[tuple[int, int | None], float] = field(default_factory=dict)
    #: per bus and node (None: all) of the cycle frames: [the last one's time, the time
    #: between them, the part of it in intervals of the config's period (within
    #: PERIOD_TOLERANCE)]
    cycle_timing: dict[tuple[int, int | None], list[float]] = field(default_factory=dict)
    #: what reading the log took (s)
    seconds: float = 0.0
    #: how far out of time order its frames are written (s): the most a frame's time is
    #: before that of a frame written earlier
    disorder: float = 0.0

    def addressed_since(self, bus: int, node: int) -> float:
        """When the master first sent to the drive ``node`` of ``bus`` or to all of the bus
        (inf: never): what the drive sent before (a boot-up at its power-on, which may come
        among the master's first frames to other drives) answers nothing."""
        return min(self.first_master_times.get((bus, node), math.inf),
                   self.first_master_times.get((bus, None), math.inf))

    @property
    def reorder_window(self) -> float:
        """How far :func:`frames` must reorder the log to read it in time order (s)."""
        return max(REORDER_WINDOW, self.disorder)

    @property
    def duration(self) -> float:
        if self.first_time is None or self.last_time is None:
            return 0.0
        return self.last_time - self.first_time

    @property
    def in_period(self) -> float:
        """The share of the time between the master's cycles (on its busiest bus) spent in
        intervals of the config's period: near 1 for a real-time run's or a robot's log,
        near 0 for a lock-step run's (nan: too few cycles)."""
        timing = max(self.cycle_timing.values(), key=lambda t: t[1], default=None)
        if timing is None or not timing[1] > 0:
            return math.nan
        return timing[2] / timing[1]

    @property
    def cycles(self) -> int:
        """The master's cycles in the log (on its busiest bus)."""
        return max((max(counts.values(), default=0) for counts in self.cycle_frames),
                   default=0)


def parse_channels(pairs: list[str], config: SystemConfig) -> dict[str, int]:
    """``--channel LOGCHANNEL=BUS`` pairs: the log's channel (as text) -> bus index."""
    names = [bus.name for bus in config.buses]
    mapping = {}
    for pair in pairs:
        channel, sep, bus = pair.partition("=")
        if not sep or bus not in names:
            raise UsageError.single(f"--channel {pair}: give LOGCHANNEL=BUS with BUS one of "
                                    f"{', '.join(names)}")
        mapping[channel] = names.index(bus)
    return mapping


class ChannelMap:
    """The log's channels -> bus index, each decided when it first comes (the rules in the
    module's docstring), so that one pass over the log does."""

    def __init__(self, config: SystemConfig, given: dict[str, int]):
        self._given = given
        self._count = len(config.buses)
        self._by_name: dict[str, int] = {}
        for index, bus in enumerate(config.buses):
            self._by_name.setdefault(str(bus.channel), index)
            self._by_name.setdefault(bus.name, index)
            self._by_name.setdefault(file_stem(bus.name), index)   # a folder's file's
        self.buses: dict[object, int] = {}
        #: channels of no bus -> [first frame number, frames]
        self.unmatched: dict[object, list[int]] = {}

    def bus(self, channel: object, number: int) -> int | None:
        """The bus of a frame's channel (None: none, counted among the unmatched)."""
        found = self.buses.get(channel)
        if found is None and channel not in self.unmatched:
            found = self._decide(channel)
            if found is not None:
                self.buses[channel] = found
        if found is None:
            self.unmatched.setdefault(channel, [number, 0])[1] += 1
        return found

    def _decide(self, channel: object) -> int | None:
        if self._given:
            return self._given.get(str(channel))
        if isinstance(channel, int) and 1 <= channel <= self._count:
            return channel - 1
        if str(channel) in self._by_name:
            return self._by_name[str(channel)]
        if self._count == 1 and not self.buses:
            return 0
        return None

    def refusal(self, config: SystemConfig, path: Path) -> ConfigError:
        listed = ", ".join(f"{c} ({n} frames from frame {first})"
                           for c, (first, n) in self.unmatched.items())
        if self._given:
            return ConfigError.single(f"{path}: channel(s) {listed} of the log have no --channel",
                                      hint="give LOGCHANNEL=BUS for each")
        return ConfigError.single(
            f"{path}: the log's channel(s) {listed} are not the config's buses "
            f"({', '.join(f'{b.name} on {b.channel}' for b in config.buses)})",
            hint="map them: --channel LOGCHANNEL=BUS for each (BLF and ASC number channels "
                 "from 1 in the config's bus order); a bench's logs, one per bus (hil_drives' "
                 "BUS.blf files): give their folder")


def frames(path: Path, config: SystemConfig, channels: dict[object, int],
           reorder_window: float = REORDER_WINDOW) -> Iterator[LoggedFrame]:
    """The log's frames told apart (after :func:`survey` accepted it), in time order (one
    bus' frames in the log's order) where the log is written at most ``reorder_window``
    out of it (:attr:`Survey.reorder_window`). Error frames are left out."""
    tellers = [BusFrames(bus) for bus in config.buses]

    def told() -> Iterator[LoggedFrame]:
        for number, msg in enumerate(read_log(path), 1):
            if msg.is_error_frame:
                continue
            bus = channels[msg.channel]
            frame = frame_of(msg)
            teller = tellers[bus]
            sensor = teller.sensor(frame)
            if sensor is not None and sensor.endswith("request"):   # a master's, to a sensor
                source: FrameSource | None = FrameSource(Sender.MASTER, None, sensor)
            else:
                source = None if sensor is not None else teller.source(frame)
            yield LoggedFrame(number, msg.timestamp, bus, frame, source)
    return in_time_order(told(), reorder_window)


def in_time_order(logged: Iterable[LoggedFrame], window: float = REORDER_WINDOW
                  ) -> Iterator[LoggedFrame]:
    """Frames by time (the log's order among equal times), for a log written up to
    ``window`` seconds out of order."""
    waiting: list[tuple[float, int, LoggedFrame]] = []
    for frame in logged:
        heapq.heappush(waiting, (frame.time, frame.number, frame))
        while waiting[0][0] < frame.time - window:
            yield heapq.heappop(waiting)[2]
    while waiting:
        yield heapq.heappop(waiting)[2]


def survey(path: Path, config: SystemConfig, given: dict[str, int]) -> Survey:
    """Read the whole log once: refuse it (ConfigError, every misfit) if it does not fit the
    config, else count what it holds."""
    begun = time.perf_counter()
    period = 1.0 / config.cycle_hz
    channels = ChannelMap(config, given)
    tellers = [BusFrames(bus) for bus in config.buses]
    result = Survey(path, channels.buses, cycle_frames=[{} for _ in tellers],
                    last_drive_time=[None] * len(tellers),
                    last_sensor_time=[None] * len(tellers))
    misfits: dict[tuple[int, int, bool], list] = {}
    newest, most_disordered = -math.inf, 0
    for number, msg in enumerate(read_log(path), 1):
        if msg.is_error_frame:
            continue
        result.frames += 1
        if result.first_time is None:
            result.first_time = msg.timestamp
        result.last_time = msg.timestamp
        newest = max(newest, msg.timestamp)
        if newest - msg.timestamp > result.disorder:
            result.disorder, most_disordered = newest - msg.timestamp, number
        bus = channels.bus(msg.channel, number)
        if bus is None:
            continue
        frame = frame_of(msg)
        if tellers[bus].sensor(frame) is not None:
            last = result.last_sensor_time[bus]
            result.last_sensor_time[bus] = msg.timestamp if last is None else max(
                last, msg.timestamp)
            continue
        source = tellers[bus].source(frame)
        if source is None:
            misfit = misfits.setdefault((bus, msg.arbitration_id, msg.is_extended_id),
                                        [number, msg.timestamp, 0])
            misfit[2] += 1
        elif source.sender is Sender.MASTER:
            addressed = (bus, source.node_id)
            result.first_master_times[addressed] = min(
                msg.timestamp, result.first_master_times.get(addressed, math.inf))
            if source.cycle:
                counts = result.cycle_frames[bus]
                counts[source.node_id] = counts.get(source.node_id, 0) + 1
                timing = result.cycle_timing.get((bus, source.node_id))
                if timing is None:
                    result.cycle_timing[bus, source.node_id] = [msg.timestamp, 0.0, 0.0]
                else:
                    interval = msg.timestamp - timing[0]
                    timing[:] = [msg.timestamp, timing[1] + interval, timing[2] + (
                        interval if abs(interval - period) < PERIOD_TOLERANCE * period
                        else 0.0)]
        else:
            last = result.last_drive_time[bus]
            result.last_drive_time[bus] = msg.timestamp if last is None else max(last,
                                                                                 msg.timestamp)
    if not result.frames:
        raise ConfigError.single(f"{path}: the log holds no CAN frame")
    if channels.unmatched:
        raise channels.refusal(config, path)
    if misfits:
        raise ConfigError(_refusal(misfits, tellers, result))
    if result.disorder > MAX_REORDER:
        raise ConfigError.single(
            f"{path}: frame {most_disordered} is written {result.disorder:.1f} s after frames "
            f"stamped later; hil replay puts a log back in time order over at most "
            f"{MAX_REORDER:g} s (it holds that much of the log to do it)",
            hint="write the log in time order: sort its frames by timestamp")
    result.seconds = time.perf_counter() - begun
    return result


def _refusal(misfits: dict[tuple[int, int, bool], list], tellers: list[BusFrames],
             found: Survey) -> list:
    start = found.first_time or 0.0
    shown = sorted(misfits.items(), key=lambda item: item[1][0])
    diagnostics = [error(
        f"{found.path}: frame 0x{can_id:03X}{' ext' if extended else ''} on bus "
        f"'{tellers[bus].name}' ({count} in all, the first at {time - start:.3f} s, frame "
        f"{number} of the log) is no frame of the bus' "
        f"drives (node ids {', '.join(map(str, tellers[bus].node_ids))}) nor of their master",
        hint="a log of another robot or bus, a node the config lacks, or channels mapped to "
             "the wrong buses (--channel LOGCHANNEL=BUS)")
        for (bus, can_id, extended), (number, time, count) in shown[:MISFITS_SHOWN]]
    if len(shown) > MISFITS_SHOWN:
        diagnostics.append(error(f"and {len(shown) - MISFITS_SHOWN} more ids that do not fit"))
    return diagnostics
