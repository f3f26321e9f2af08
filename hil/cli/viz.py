"""``hil viz CONFIG [CONFIG ...]``: log running robots to rerun (viewer, .rrd file, or both);
several robots share one recording, each under ``/<robot>/``."""

from __future__ import annotations

import argparse
import os
import signal
import tempfile
from pathlib import Path

import rerun as rr

from hil.bus_config import SystemConfig, check_together, load_bus_config, open_buses
from hil.can.monitor import BusMonitor
from hil.cli import common
from hil.cli.written_files import previous_outputs
from hil.errors import UsageError
from hil.realtime import enter_background, leave_background
from hil.visualisation import RunRecorder
from hil.visualisation.blueprint import run_blueprint
from hil.visualisation.node import VizNode
from hil.visualisation.of_config import config_recorder
from hil.visualisation.segments import SegmentLimit, Segments
from hil.zenoh_session import ZenohSettings, close_all, session


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("config", nargs="+",
                        help="bus config, e.g. bus_config/ur3.yaml, or a robot's name (ur3, "
                             "pigot); several: one recording of them all, each robot's "
                             "entities under /<robot>/")
    sinks = parser.add_argument_group(
        "rerun", "where the recording goes (several may be given); default: a spawned viewer "
                 "where a display exists, else --save run.rrd")
    sinks.add_argument("--save", type=Path, metavar="FILE.rrd", help="record to an .rrd file")
    sinks.add_argument("--segment", type=SegmentLimit.parse, metavar="LIMIT",
                       help="with --save, record in segments FILE-0001.rrd, FILE-0002.rrd, ... "
                            "each closed at LIMIT, a size (500MB) or a time (10m): a crash "
                            "loses at most the last, and each opens alone")
    sinks.add_argument("--spawn", action="store_true", help="spawn a rerun viewer")
    sinks.add_argument("--viewer", metavar="URL",
                       help="stream to a running viewer, e.g. rerun+http://HOST:9876/proxy")
    sinks.add_argument("--serve", action="store_true",
                       help="serve the web viewer (prints its address)")
    parser.add_argument("--can-log", type=Path, metavar="FILE",
                        help="also write every CAN frame to FILE (python-can's format by "
                             "suffix: .blf Vector's binary log, channels numbered in the "
                             "config's bus order; .log candump's text, channels named; .asc, "
                             ".trc, .csv)")
    parser.add_argument("--no-can", action="store_true",
                        help="do not open the CAN buses (no bus load, no CAN log): for a host "
                             "that cannot reach them")
    common.add_timing(parser, "following a lock-step run: schedule normally (in real time the "
                              "visualiser runs under SCHED_IDLE, never taking the drives' or "
                              "the controller's time; in lock-step nothing has a deadline, and "
                              "starved it would lose CAN frames from its sockets' buffers)")
    parser.add_argument("--normal-scheduling", action="store_true",
                        help="in real time too, schedule normally, not under SCHED_IDLE: for a "
                             "visualiser on a host of its own (no real-time process to give "
                             "way to), or beside a load that would starve it under SCHED_IDLE "
                             "(its summary counts the cycles it lost)")
    parser.add_argument("--status-period", type=common.duration_or_zero, default=0.0,
                        metavar="TIME",
                        help="print a status line every TIME, e.g. 5s (cycles, losses, the "
                             "recording's lag since the last); default 0: never")
    common.add_cpus(parser)
    common.add_can_override(parser)
    common.add_package_path(parser)
    common.add_zenoh(parser, "observer")


def run(args: argparse.Namespace) -> int:
    configs = [load_bus_config(common.config_path(c), common.package_path(args))
               for c in args.config]
    check_together(configs)
    if args.no_can and args.can_log:
        raise UsageError.single("--can-log needs the CAN buses, but --no-can was given")
    if len(configs) > 1 and (args.channel or args.interface):
        raise UsageError.single("--channel and --interface are for one robot's buses",
                                hint="give the robots' channels in their bus configs")
    zenoh = common.zenoh_settings(args)
    background = not (args.timing.lock_step or args.normal_scheduling)
    if background:
        enter_background()      # never the real-time processes' time (its threads inherit it)
    common.keep_on_cpus(args)
    names = "+".join(c.robot.name for c in configs)
    recording = rr.RecordingStream("hil", recording_id=f"{names}-{os.getpid()}")
    sinks = _sinks(args)
    sinks.attach(recording)
    with tempfile.TemporaryDirectory(prefix="hil-viz-") as folder:
        recorders = [config_recorder(recording, config, Path(folder), len(configs) > 1)
                     for config in configs]

        def begin() -> None:
            """What every segment starts with: the static data and the layout."""
            for recorder in recorders:
                recorder.log_static()
            recording.send_blueprint(run_blueprint([r.view() for r in recorders],
                                                   lock_step=args.timing.lock_step))

        def roll() -> None:
            """A full segment: flushed and closed, the next begun."""
            if sinks.segments is not None and sinks.segments.full():
                for recorder in recorders:
                    recorder.flush()
                recording.flush()
                sinks.next_segment(recording)
                begin()

        begin()
        monitor = None if args.no_can else _monitor(configs, recorders, zenoh, args)
        node = VizNode(recorders, session(zenoh), monitor, roll,
                       status_period=args.status_period)

        def stop() -> None:
            if background:      # what is left to do is bounded (VizNode's drain, the flush)
                leave_background()
            node.stop()

        previous = common.on_stop_signals(stop)
        print(f"hil viz: {', '.join(c.robot.name for c in configs)}; {sinks.described}"
              + (f"; CAN log {args.can_log}" if args.can_log else ""), flush=True)
        buses = []
        try:
            node.run()
        finally:
            if monitor is not None:
                monitor.close()
                # what the CAN log and the bus-load plot missed: a visualiser that falls
                # behind loses frames (the transport drops them rather than stall a sender)
                buses = common.bus_report(monitor.buses, monitor.channel_numbers)
            for recorder in recorders:
                recorder.flush()
            recording.flush()
            close_all()
            for signum, handler in previous.items():
                signal.signal(signum, handler)
    for line in buses:
        print(f"hil viz: CAN monitor, {line}", flush=True)
    print(f"hil viz: {node.summary()}", flush=True)
    return 0


class _Sinks:
    """Where the recording goes: live sinks (a viewer), and a file, whole or in segments."""

    def __init__(self, live: list, save: Path | None, segments: Segments | None,
                 described: str):
        self.live, self.save, self.segments, self.described = live, save, segments, described

    def attach(self, recording: rr.RecordingStream) -> None:
        file = (self.segments.current if self.segments is not None else self.save)
        sinks = [*self.live, *([rr.FileSink(str(file))] if file is not None else [])]
        if sinks:
            recording.set_sinks(*sinks)

    def next_segment(self, recording: rr.RecordingStream) -> None:
        """The file goes on in the next segment (the live sinks are set again with it)."""
        self.segments.advance()
        self.attach(recording)


def _sinks(args: argparse.Namespace) -> _Sinks:
    """The sinks the options ask for, in words too."""
    spawn, save = args.spawn, args.save
    if not (spawn or save or args.viewer or args.serve):
        if common.display_available():
            spawn = True
        else:
            save = Path("run.rrd")
    if args.segment is not None and save is None:
        raise UsageError.single("--segment divides the file of --save: give --save FILE.rrd")
    if args.segment is not None and args.serve:
        # each segment sets the sinks anew: a client reconnects, a server would bind again
        raise UsageError.single("--segment and --serve together: the web viewer's server would "
                                "start again with each segment",
                                hint="stream to a viewer with --viewer URL, or --spawn")
    outputs = {"--save": save} if save else {}
    if args.can_log:
        outputs["--can-log"] = args.can_log
    # checked before a viewer starts (hil.cli.written_files)
    replaced = previous_outputs(outputs, recording=save)
    live, words = [], []
    if spawn:
        rr.spawn(connect=False)
        live.append(rr.GrpcSink())
        words.append("viewer spawned")
    if args.viewer:
        live.append(rr.GrpcSink(args.viewer))
        words.append(f"streaming to {args.viewer}")
    if args.serve:
        server = rr.GrpcServerSink()
        live.append(server)
        rr.serve_web_viewer(connect_to=server.uri, open_browser=False)
        words.append(f"web viewer at http://localhost:9090 (data at {server.uri})")
    if replaced:
        words.append(f"replacing {', '.join(replaced)}")
    segments = None
    if save:
        if args.segment is not None:
            segments = Segments(save, args.segment)
            words.append(f"recording to {segments.current} and on, segments of {args.segment}")
        else:
            words.append(f"recording to {save}")
    return _Sinks(live, save, segments, ", ".join(words))


def _monitor(configs: list[SystemConfig], recorders: list[RunRecorder], zenoh: ZenohSettings,
             args: argparse.Namespace) -> BusMonitor:
    """One monitor of every robot's buses (one CAN log), each named as its recorder names
    it."""
    interface, channels = common.can_overrides(args)
    buses, channel_of, bitrates = {}, {}, {}
    for config, recorder in zip(configs, recorders):
        opened = open_buses(config, zenoh, interface, channels, logging=True)
        for name, bus in recorder.monitor_names.items():
            buses[name] = opened[bus]
            config_bus = next(b for b in config.buses if b.name == bus)
            channel_of[name] = channels.get(bus, config_bus.channel)
            bitrates[name] = config_bus.bit_rates
    # hil's buses opened for logging stamp each frame with its sender's clock (socketcan's
    # with the kernel's): counted by it (hil.can.monitor.BusLoadMeter says why)
    return BusMonitor(buses, channel_of, bitrates, args.can_log, by_timestamp=True)
