"""``hil up [ROBOT|CONFIG ...]``: sim, controller and visualiser as processes, one command.

The seed's launch file, reborn: each part is its own ``hil`` process (so any
of them could run elsewhere), started in order and waited for through its
Zenoh liveliness token. ``hil up`` then optionally runs a demo goal, shows
progress, and stops everything in a known order: controller first (goal
aborted, drives disabled), then the visualiser (recording flushed), then the
sim. A child that dies early ends the run with status 1 and its last log
lines. The controller's faults (its diagnostics) are printed as they happen
and, unless ``--fault`` injected them, end the run with status 1 too.
Children run in their own session, so Ctrl-C reaches ``hil up`` only, and
they stop themselves if ``hil up`` is killed.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from pathlib import Path

from hil.bus_config import check_together, load_bus_config
from hil.bus_config.locate import shipped_names
from hil.can.faults import ProcessFault, parse_fault
from hil.cli import common
from hil.cli.run_progress import Progress
from hil.cli.up.children import make_children, start_in_order
from hil.cli.up.demo import supervise
from hil.cli.up.outputs import replace_previous
from hil.cli.up.robots import RobotRun
from hil.errors import UsageError
from hil.realtime.stalls import BENCH_STALL_STATUS
from hil.supervisor import ChildFailed, Child, Run, kill_later, viz_summary
from hil.visualisation.segments import SegmentLimit, segment_files
from hil.zenoh_security import Identity
from hil.zenoh_session import ZenohSettings, close_all, meeting_endpoint


#: the CAN log's format in words, by suffix
CAN_LOG_FORMATS = {".blf": "Vector BLF", ".log": "candump", ".asc": "Vector ASC",
                   ".trc": "PEAK TRC", ".csv": "python-can CSV"}



def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        "start sim, controller and visualiser together (optionally run a demo), record the "
        "run; several robots (hil up ur3 pigot): a sim and a controller each, one visualiser "
        "recording them all, the demos run together")
    parser.epilog = (
        "exit status: 0 the run (and the demo) succeeded; 1 the controller reported a drive "
        "fault that no stall of the bench explains (a device fault, injected ones included), "
        "the demo failed without a fault, or a process failed; "
        f"{BENCH_STALL_STATUS} every fault the controller reported (and so a demo they "
        "aborted) was explained by a measured stall of the bench's own simulator, controller "
        "or Zenoh transport, a controller's bring-up failed while the bench itself stalled, "
        "or the bench stalled more than --max-stalls times (the bench "
        "broke real time: a flaky host, not a regression); 130 interrupted. With several "
        f"robots, the worst of theirs (1, then {BENCH_STALL_STATUS})")
    parser.add_argument("target", nargs="*", metavar="ROBOT|CONFIG",
                        help=f"a robot with a config in bus_config/ ({shipped_names()}) or a bus config "
                             "path (default: pigot); several: each robot's entities go under "
                             "/<robot>/ in the recording, its process logs are "
                             "<robot>.sim.log and <robot>.control.log, and with --ros it is "
                             "in the namespace <--ros-namespace>/<robot>")
    parser.add_argument("--demo", action="store_true",
                        help="run a goal that moves every axis (and opens/closes grippers), "
                             "then stop")
    parser.add_argument("--keep-running", action="store_true",
                        help="after the demo, keep running until Ctrl-C")
    parser.add_argument("--duration", type=common.duration, metavar="TIME",
                        help="without --demo: stop after TIME, e.g. 30s, 10min (default: run "
                             "until Ctrl-C)")
    parser.add_argument("--save", type=Path, default=Path("run.rrd"), metavar="FILE.rrd",
                        help="the rerun recording (default run.rrd); the CAN log "
                             "(FILE.can.blf) and the processes' logs (FILE.logs/) go beside it; "
                             "a previous run's are replaced, each named first")
    parser.add_argument("--segment", type=_segment_limit, metavar="LIMIT",
                        help="record in segments FILE-0001.rrd, FILE-0002.rrd, ... each closed at "
                             "LIMIT, a size (500MB) or a time (10m): a crash loses at most the "
                             "last, and each opens alone (hil review finds them all)")
    parser.add_argument("--can-log", type=Path, metavar="FILE",
                        help="the CAN log instead of FILE.can.blf, in python-can's format by "
                             "suffix: .blf Vector's binary log (the default: about 12x smaller "
                             "than candump's text), channels numbered in the config's bus "
                             "order (printed at the end); .log candump's text, channels named; "
                             ".asc, .trc, .csv")
    common.add_timing(parser, "sim and controller in lock-step (reproducible, as fast as they go)")
    parser.add_argument("--can", action="append", default=[], metavar="CHANNEL",
                        help="use SocketCAN: one channel per bus of the config, in its order "
                             "(e.g. --can vcan0 --can vcan1)")
    parser.add_argument("--spawn", action="store_true",
                        help="also spawn a rerun viewer (default where a display exists)")
    parser.add_argument("--no-viewer", action="store_true", help="never spawn a viewer")
    parser.add_argument("--max-stalls", type=int, metavar="N",
                        help="real time: stop the run once the bench has stalled more than N "
                             "times (the sim's or the controller's loop, or a Zenoh delivery, "
                             f"over 5 ms late), exit status {BENCH_STALL_STATUS}, as Simulink "
                             "Real-Time's Max Overloads (0: at the first); default: no limit, "
                             "each stall is counted, reported and held against the faults")
    parser.add_argument("--fault", action="append", default=[], metavar="SPEC",
                        help="inject a fault (repeatable): the sim's (drop:BUS:FRACTION, "
                             "delay:BUS:FRACTION:MS, corrupt:BUS:FRACTION, silence:BUS/NODE@S, "
                             "fault:BUS/NODE@S: S seconds of the plant's time after every "
                             "drive is enabled; silence|freeze|spike:SENSOR@S: seconds of the "
                             "plant's time), or kill:sim|control|viz@S (seconds after all are "
                             "up)")
    parser.add_argument("--viewer", metavar="URL", help="also stream to a running rerun viewer")
    parser.add_argument("--secure", type=Path, metavar="DIR",
                        help="mutual TLS between the processes with the keys of `hil keys init "
                             "DIR`, each in its role (sim: drives, control: controller, viz: "
                             "observer, this process' goals: operator)")
    common.add_ros(parser, "sim and control also appear in ROS 2 (see hil sim/control --help)")
    parser.add_argument("--ros-use-sim-time", action="store_true",
                        help="with --ros: the controller stamps on the plant's time (/clock)")
    common.add_can_override(parser)
    common.add_package_path(parser)


def run(args: argparse.Namespace) -> int:
    paths = [common.config_path(target) for target in args.target or ["pigot"]]
    configs = [load_bus_config(path, common.package_path(args)) for path in paths]
    check_together(configs)
    several = len(configs) > 1
    if several and (args.can or args.channel or args.fault):
        raise UsageError.single("--can, --channel and --fault name one robot's buses and "
                                "processes", hint="run that robot alone with them")
    for config in configs:
        for warning in config.warnings:
            print(warning, file=sys.stderr)
    common.ros_settings(args)                       # a bad --ros option fails here, not later
    faults = [parse_fault(text) for text in args.fault]
    save = args.save
    logs = save.with_name(save.stem + ".logs")
    can_log = args.can_log or save.with_name(save.stem + ".can.blf")
    replaced = replace_previous(save, can_log, logs)
    if replaced:
        print(f"hil up: replacing the previous run's {', '.join(replaced)} (keep a run: move "
              "it, or give --save another name)", flush=True)
    logs.mkdir(parents=True, exist_ok=True)
    timing = args.timing
    stop = threading.Event()
    robots = [RobotRun(path, config, Progress(None if timing.lock_step else args.max_stalls,
                                            stop.set, f"{config.robot.name}: " if several else ""))
              for path, config in zip(paths, configs)]
    viz = make_children(args, robots, faults, logs, can_log)
    supervised = Run([], stop)
    previous = common.on_stop_signals(stop.set)
    for robot in robots:
        print(f"hil up: {robot.name} from {robot.config_path}; Zenoh {meeting_endpoint()}; "
              f"{timing}; process logs in {logs}/", flush=True)
    zenoh = ZenohSettings.meeting(Identity.of(args.secure, "operator") if args.secure else None)
    status = 0
    watchers: list = []
    try:
        start_in_order(robots, viz, supervised, zenoh, watchers,
                       together=args.timing.lock_step)
        for robot in robots:
            robot.progress.count_stalls()
        if not stop.is_set():
            for kill in (f for f in faults if isinstance(f, ProcessFault)):
                child = viz if kill.process == "viz" else robots[0].children[kill.process]
                threading.Thread(target=kill_later, args=(child, kill.at, stop),
                                 daemon=True).start()
            supervise(args, robots, supervised, zenoh)
    except ChildFailed as exc:
        print(f"hil up: {exc}", file=sys.stderr, flush=True)
        status = 1
        if exc.status == BENCH_STALL_STATUS:       # only a controller's bring-up ends so
            print("hil up: the controller's bring-up failed while the bench itself stalled "
                  "(its error above names the stalls): the bench broke real time, the device "
                  f"need not have failed; exit status {BENCH_STALL_STATUS}", file=sys.stderr,
                  flush=True)
            status = BENCH_STALL_STATUS
    finally:
        try:
            too_many = [r for r in robots if r.progress.too_many is not None]
            if too_many:
                for robot in too_many:
                    print(f"hil up: {robot.label}the bench stalled more than --max-stalls "
                          f"{args.max_stalls} times (the last: {robot.progress.too_many}): "
                          f"run stopped, exit status {BENCH_STALL_STATUS}", file=sys.stderr,
                          flush=True)
                status = BENCH_STALL_STATUS
            elif stop.is_set():
                print("hil up: interrupted", flush=True)
                status = 130
            print("hil up: stopping control, viz and sim", flush=True)
        finally:        # whatever went wrong above: no process is left behind
            problems = supervised.shut_down()
            for watcher in watchers:
                watcher.close()
            close_all()
            for signum, handler in previous.items():
                signal.signal(signum, handler)
    for robot in robots:
        for problem in robot.progress.problems[:5]:
            print(f"hil up: {robot.label}{problem}", file=sys.stderr)
    for problem in problems:
        print(f"hil up: {problem}", file=sys.stderr)
    if problems and status == 0:
        status = 1
    if status == 0:
        status = _outcome(robots)
    if not timing.lock_step:
        for robot in robots:
            with robot.progress.lock:
                print(f"hil up: {robot.label}the bench since the controller's bring-up: "
                      f"{robot.progress.stalls.summary()} (sim, control: their loops; "
                      f"transport: Zenoh's deliveries)", flush=True)
    _report_outputs(save, can_log, viz)
    return status


def _outcome(robots: list[RobotRun]) -> int:
    """After a run no process failed, robot by robot: 0 without faults and with its demo
    (if any) succeeded; BENCH_STALL_STATUS when the bench's own stalls explain every fault
    (a demo aborted by them too); else 1; says which. The worst of them: 1, then 3, then 0."""
    statuses = [0]
    for robot in robots:
        reported, explained = robot.progress.faults(), robot.progress.explained()
        if not reported:
            statuses.append(0 if robot.demo_succeeded else 1)
            continue
        story = f"the whole story: {robot.children['control'].log_path}"
        if explained >= reported:
            print(f"hil up: {robot.label}the controller reported {reported} fault(s), each "
                  f"explained by a stall of the bench itself (above): the bench broke real "
                  f"time, the device did not fail; exit status {BENCH_STALL_STATUS} ({story})",
                  file=sys.stderr)
            statuses.append(BENCH_STALL_STATUS)
        else:
            print(f"hil up: {robot.label}the controller reported {reported} fault(s), above, "
                  f"{reported - explained} of them not explained by a stall of the bench; the "
                  f"drives were stopped ({story})", file=sys.stderr)
            statuses.append(1)
    return 1 if 1 in statuses else max(statuses)


def _segment_limit(text: str) -> str:
    """``--segment``'s value, checked here (hil viz takes it as given)."""
    SegmentLimit.parse(text)
    return text


def _report_outputs(save: Path, can_log: Path, viz: Child) -> None:
    kind = CAN_LOG_FORMATS.get(can_log.suffix.lower(), can_log.suffix.lstrip("."))
    segments = [path for path in segment_files(save) if path.is_file()]
    size = sum(path.stat().st_size for path in segments) / 1e6
    if segments == [save]:
        print(f"hil up: rerun recording: {save} ({size:.1f} MB)")
    elif segments:
        print(f"hil up: rerun recording: {len(segments)} segment(s), {segments[0]} ... "
              f"{segments[-1].name} ({size:.1f} MB)")
    if can_log.is_file():
        print(f"hil up: CAN log ({kind}): {can_log} ({can_log.stat().st_size / 1e6:.1f} MB)")
    if viz.process is not None:
        lines = [line.strip().removeprefix("hil viz: ") for line in viz.last_lines().splitlines()]
        for line in lines:
            if line.startswith("CAN monitor, "):
                print(f"hil up: CAN log, {line.removeprefix('CAN monitor, ')}")
        summary = viz_summary(viz)
        if summary:
            print(f"hil up: recorded {summary}")
    if segments:
        beside = Path(sys.executable).with_name("hil")        # the venv's hil, if any
        print(f"hil up: review with: {beside if beside.exists() else 'hil'} review {save}")
