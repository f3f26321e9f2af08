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
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path


from hil.bus_config import SystemConfig, check_together, load_bus_config
from hil.cli import common
from hil.cli.run_progress import Progress
from hil.controllers import GoalRejected, GoalStatus
from hil.commissioning.demo_pace import MOTION_SHARE, paced_demo
from hil.commissioning.stance import stance
from hil.can.faults import ProcessFault, parse_fault
from hil.errors import HilError
from hil.hardware import BOOT_TIMEOUT
from hil.messaging.zenoh_api import (
    ControllerGone, ProcessWatch, RunSubscriber, TrajectoryActionClient,
)
from hil.visualisation.segments import SegmentLimit, segment_files
from hil.supervisor import (
    Child, ChildFailed, Run, cpus_argument, kill_later, viz_summary, wait_alive,
)
from hil.realtime import enter_background, real_time_cpus
from hil.zenoh_security import Identity
from hil.zenoh_session import ZenohSettings, close_all, free_loopback_port, session


#: the visualiser's status lines (cycles, losses, the recording's lag) in viz.log, every (s)
VIZ_STATUS_PERIOD = 60
#: the CAN log's format in words, by suffix
CAN_LOG_FORMATS = {".blf": "Vector BLF", ".log": "candump", ".asc": "Vector ASC",
                   ".trc": "PEAK TRC", ".csv": "python-can CSV"}

#: exit status: every fault the controller reported was explained by a stall of the bench's
#: own real-time processes (the simulator's, the controller's, the Zenoh transport's), or the
#: run passed --max-stalls: the bench broke real time, the device did not fail (1: the device
#: reported a fault, or a process failed)
BENCH_FAULT_STATUS = 3


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        "start sim, controller and visualiser together (optionally run a demo), record the "
        "run; several robots (hil up ur3 pigot): a sim and a controller each, one visualiser "
        "recording them all, the demos run together")
    parser.epilog = (
        "exit status: 0 the run (and the demo) succeeded; 1 the controller reported a drive "
        "fault that no stall of the bench explains (a device fault, injected ones included), "
        "the demo failed without a fault, or a process failed; "
        f"{BENCH_FAULT_STATUS} every fault the controller reported (and so a demo they "
        "aborted) was explained by a measured stall of the bench's own simulator, controller "
        "or Zenoh transport, or the bench stalled more than --max-stalls times (the bench "
        "broke real time: a flaky host, not a regression); 130 interrupted. With several "
        f"robots, the worst of theirs (1, then {BENCH_FAULT_STATUS})")
    parser.add_argument("target", nargs="*", metavar="ROBOT|CONFIG",
                        help="a robot with a config in bus_config/ (pigot, ur3) or a bus config "
                             "path (default: pigot); several: each robot's entities go under "
                             "/<robot>/ in the recording, its process logs are "
                             "<robot>.sim.log and <robot>.control.log, and with --ros it is "
                             "in the namespace <--ros-namespace>/<robot>")
    parser.add_argument("--demo", action="store_true",
                        help="run a goal that moves every axis (and opens/closes grippers), "
                             "then stop")
    parser.add_argument("--keep-running", action="store_true",
                        help="after the demo, keep running until Ctrl-C")
    parser.add_argument("--duration", type=float, metavar="S",
                        help="without --demo: stop after S seconds (default: run until Ctrl-C)")
    parser.add_argument("--save", type=Path, default=Path("run.rrd"), metavar="FILE.rrd",
                        help="the rerun recording (default run.rrd); the CAN log "
                             "(FILE.can.blf) and the processes' logs (FILE.logs/) go beside it")
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
    timing = parser.add_mutually_exclusive_group()
    timing.add_argument("--lock-step", dest="timing", action="store_const", const="lock-step",
                        help="sim and controller in lock-step (reproducible, as fast as they go)")
    timing.add_argument("--real-time", dest="timing", action="store_const", const="real-time",
                        help="sim and controller on the wall clock (the default)")
    parser.add_argument("--can", action="append", default=[], metavar="CHANNEL",
                        help="use SocketCAN: one channel per bus of the config, in its order "
                             "(e.g. --can vcan0 --can vcan1)")
    parser.add_argument("--spawn", action="store_true",
                        help="also spawn a rerun viewer (default where a display exists)")
    parser.add_argument("--no-viewer", action="store_true", help="never spawn a viewer")
    parser.add_argument("--max-stalls", type=int, metavar="N",
                        help="real time: stop the run once the bench has stalled more than N "
                             "times (the sim's or the controller's loop, or a Zenoh delivery, "
                             f"over 5 ms late), exit status {BENCH_FAULT_STATUS}, as Simulink "
                             "Real-Time's Max Overloads (0: at the first); default: no limit, "
                             "each stall is counted, reported and held against the faults")
    parser.add_argument("--fault", action="append", default=[], metavar="SPEC",
                        help="inject a fault (repeatable): the sim's (drop:BUS:FRACTION, "
                             "delay:BUS:FRACTION:MS, corrupt:BUS:FRACTION, silence:BUS/NODE@S, "
                             "fault:BUS/NODE@S: S seconds of the plant's time after every "
                             "drive is enabled), or kill:sim|control|viz@S (seconds after all "
                             "are up)")
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


@dataclass
class _Robot:
    """One robot under ``hil up``: its config, its sim and controller, and what is followed
    of its run."""

    config_path: Path
    config: SystemConfig
    progress: Progress
    children: dict[str, Child] = field(default_factory=dict)
    #: whether its demo (if any) succeeded
    demo_succeeded: bool = True

    @property
    def name(self) -> str:
        return self.config.robot.name

    @property
    def label(self) -> str:
        """Before what ``hil up`` says of this robot ("" with one robot, "ur3: " with
        several)."""
        return self.progress.label


def run(args: argparse.Namespace) -> int:
    paths = [common.config_path(target) for target in args.target or ["pigot"]]
    configs = [load_bus_config(path, common.package_path(args)) for path in paths]
    check_together(configs)
    several = len(configs) > 1
    if several and (args.can or args.channel or args.fault):
        raise HilError.single("--can, --channel and --fault name one robot's buses and "
                              "processes", hint="run that robot alone with them")
    for config in configs:
        for warning in config.warnings:
            print(warning, file=sys.stderr)
    common.ros_settings(args)                       # a bad --ros option fails here, not later
    faults = [parse_fault(text) for text in args.fault]
    save = args.save
    logs = save.with_name(save.stem + ".logs")
    logs.mkdir(parents=True, exist_ok=True)
    can_log = args.can_log or save.with_name(save.stem + ".can.blf")
    endpoint = f"tcp/127.0.0.1:{free_loopback_port()}"
    timing = args.timing or "real-time"
    stop = threading.Event()
    robots = [_Robot(path, config, Progress(args.max_stalls if timing == "real-time" else None,
                                            stop.set, f"{config.robot.name}: " if several else ""))
              for path, config in zip(paths, configs)]
    viz = _children(args, robots, faults, endpoint, logs, can_log)
    supervised = Run([], stop)
    previous = {s: signal.signal(s, lambda *_: stop.set()) for s in (signal.SIGINT,
                                                                      signal.SIGTERM)}
    for robot in robots:
        print(f"hil up: {robot.name} from {robot.config_path}; Zenoh {endpoint}; {timing}; "
              f"process logs in {logs}/", flush=True)
    zenoh = ZenohSettings(connect=(endpoint,), identity=Identity.of(args.secure, "operator")
                          if args.secure else None)
    status = 0
    watchers: list = []
    try:
        _start(robots, viz, supervised, zenoh, watchers)
        for robot in robots:
            robot.progress.count_stalls()
        if not stop.is_set():
            for kill in (f for f in faults if isinstance(f, ProcessFault)):
                child = viz if kill.process == "viz" else robots[0].children[kill.process]
                threading.Thread(target=kill_later, args=(child, kill.at, stop),
                                 daemon=True).start()
            _supervise(args, robots, supervised, zenoh)
    except ChildFailed as exc:
        print(f"hil up: {exc}", file=sys.stderr, flush=True)
        status = 1
    finally:
        too_many = [r for r in robots if r.progress.too_many is not None]
        if too_many:
            for robot in too_many:
                print(f"hil up: {robot.label}the bench stalled more than --max-stalls "
                      f"{args.max_stalls} times (the last: {robot.progress.too_many}): run "
                      f"stopped, exit status {BENCH_FAULT_STATUS}", file=sys.stderr, flush=True)
            status = BENCH_FAULT_STATUS
        elif stop.is_set():
            print("hil up: interrupted", flush=True)
            status = 130
        print("hil up: stopping control, viz and sim", flush=True)
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
    if timing == "real-time":
        for robot in robots:
            with robot.progress.lock:
                print(f"hil up: {robot.label}the bench's {robot.progress.stalls.summary()} "
                      f"since the controller cycled (sim, control: their loops; transport: "
                      f"Zenoh's deliveries)", flush=True)
    _report_outputs(save, can_log, viz)
    return status


def _children(args: argparse.Namespace, robots: list[_Robot], faults: list, endpoint: str,
              logs: Path, can_log: Path) -> Child:
    """Each robot's sim and control (into its ``children``) and the one visualiser (returned)
    as ``hil`` commands, placed on the CPUs in real time. The first robot's sim listens on
    ``endpoint``; every other process connects there (Zenoh's gossip links the rest)."""
    several = len(robots) > 1
    sim_faults = [f"--fault={text}" for text, f in zip(args.fault, faults)
                  if not isinstance(f, ProcessFault)]
    shared = [*(["--secure", str(args.secure)] if args.secure else []),
              *(f"--package-path={p}" for p in args.package_path)]
    lock_step = ["--lock-step"] if args.timing == "lock-step" else []
    # over TLS the processes are not pinned to a CPU each: pinned, every `hil up ur3 --secure`
    # on 2 CPUs faulted within a second as soon as a third process took the traffic (the
    # transport 40-107 ms late), unpinned 3 of 3 ran clean (docs/performance.md)
    placed = {name: [] if lock_step or args.secure else cpus_argument(cpus)
              for name, cpus in zip(("sim", "control", "viz"), real_time_cpus())}
    for index, robot in enumerate(robots):
        config = [str(robot.config_path), *_can_options(args, robot.config), *shared]
        ros = _ros_options(args, robot.name, several)
        tag = robot.name if several else ""         # in its messages and its logs' names
        prefix = f"{tag}." if tag else ""
        meet = ["--listen" if index == 0 else "--connect", endpoint]
        robot.children = {
            "sim": Child("sim", ["sim", *config, *lock_step, *placed["sim"], *meet,
                                 "--status-period", "0", *sim_faults, *ros],
                         logs / f"{prefix}sim.log", tag),
            "control": Child("control", [
                "control", *config, *lock_step, *placed["control"], "--connect", endpoint, *ros,
                # the sim already runs: a drive silent at boot is a fault
                "--boot-timeout", f"{BOOT_TIMEOUT:g}",
                *(["--ros-use-sim-time"] if args.ros_use_sim_time else [])],
                logs / f"{prefix}control.log", tag),
        }
    return Child("viz", ["viz", *(str(r.config_path) for r in robots),
                         *_can_options(args, robots[0].config), *shared, *lock_step,
                         *placed["viz"], "--connect", endpoint, "--save", str(args.save),
                         *(["--segment", args.segment] if args.segment else []),
                         # a line a minute in viz.log: the recording's lag over a long run
                         "--status-period", str(VIZ_STATUS_PERIOD),
                         "--can-log", str(can_log), *_viewer_options(args)],
                 logs / "viz.log")


def _ros_options(args: argparse.Namespace, robot: str, several: bool) -> list[str]:
    """The ``--ros`` options of a robot's processes: with several robots each in a namespace
    of its own under ``--ros-namespace`` (``/ur3``, ``/pigot``), as their topics and
    services would otherwise be one robot's."""
    options = common.ros_options(args)
    if options and several:
        namespace = f"{(args.ros_namespace or '').rstrip('/')}/{robot}"
        options = [o for o in options if not o.startswith("--ros-namespace=")]
        options.append(f"--ros-namespace={namespace}")
    return options


def _start(robots: list[_Robot], viz: Child, supervised: Run, zenoh: ZenohSettings,
           watchers: list) -> None:
    """Start the sims, the visualiser and the controllers in turn, each once the one before
    is alive on Zenoh; the watchers it makes go into ``watchers`` (to be closed however the
    start ends)."""
    watches: dict[str, ProcessWatch] = {}

    def started(child: Child, robot: _Robot) -> None:
        child.start()
        supervised.children.append(child)
        if not watches:            # the first sim listens on the endpoint: now it can be reached
            for each in robots:
                watches[each.name] = ProcessWatch(session(zenoh), each.name)
                progress = each.progress
                watchers.extend([watches[each.name], RunSubscriber(
                    session(zenoh), each.name, progress.on_samples, lambda wall, sim: None,
                    progress.problems.append, progress.on_diagnostic, progress.on_stall)])
        wait_alive(supervised, watches[robot.name].wait_alive, child)

    # the visualiser starts before the controllers: its start-up (rerun, the robot models)
    # is CPU-heavy, and must not starve the first real-time cycles
    for robot in robots:
        started(robot.children["sim"], robot)
        if supervised.stop.is_set():
            return
    viz.start()
    supervised.children.append(viz)
    # the one visualiser declares itself for every robot
    wait_alive(supervised, lambda name, timeout: all(
        watches[robot.name].wait_alive(name, timeout) for robot in robots), viz)
    if supervised.stop.is_set():
        return
    for robot in robots:
        started(robot.children["control"], robot)
        if supervised.stop.is_set():
            return


def _outcome(robots: list[_Robot]) -> int:
    """After a run no process failed, robot by robot: 0 without faults and with its demo
    (if any) succeeded; BENCH_FAULT_STATUS when the bench's own stalls explain every fault
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
                  f"time, the device did not fail; exit status {BENCH_FAULT_STATUS} ({story})",
                  file=sys.stderr)
            statuses.append(BENCH_FAULT_STATUS)
        else:
            print(f"hil up: {robot.label}the controller reported {reported} fault(s), above, "
                  f"{reported - explained} of them not explained by a stall of the bench; the "
                  f"drives were stopped ({story})", file=sys.stderr)
            statuses.append(1)
    return 1 if 1 in statuses else max(statuses)


def _can_options(args: argparse.Namespace, config: SystemConfig) -> list[str]:
    options = [f"--channel={c}" for c in args.channel]
    if args.interface:
        options.append(f"--interface={args.interface}")
    if args.can:
        if len(args.can) != len(config.buses):
            raise HilError.single(
                f"--can gave {len(args.can)} channel(s) for {len(config.buses)} bus(es) "
                f"({', '.join(b.name for b in config.buses)})", config.path,
                hint="give one --can CHANNEL per bus, in the config's order")
        options = ["--interface=socketcan"] + [f"--channel={bus.name}={channel}" for bus, channel
                                               in zip(config.buses, args.can)]
    return options


def _viewer_options(args: argparse.Namespace) -> list[str]:
    options = []
    if args.spawn or (not args.no_viewer and common.display_available()):
        options.append("--spawn")
    if args.viewer:
        options += ["--viewer", args.viewer]
    return options


def _supervise(args, robots: list[_Robot], run: Run, zenoh: ZenohSettings) -> None:
    """Run for ``--duration`` (or until stopped), or each robot's demo (``demo_succeeded``)."""
    if not args.demo:
        limit = args.duration if args.duration is not None else float("inf")
        started = time.monotonic()
        while not run.stop.is_set() and time.monotonic() - started < limit:
            run.wait(min(1.0, limit - (time.monotonic() - started)))
            for robot in robots:
                print(f"  [{time.monotonic() - started:6.1f} s]  {robot.label}"
                      f"{robot.progress.line()}", flush=True)
        return
    # the robots' demos run together, each in a thread of its own; a child that dies ends
    # them all (ChildFailed, raised here from the thread that found it)
    with ThreadPoolExecutor(len(robots), thread_name_prefix="demo") as pool:
        demos = [pool.submit(_demo, robot, run, zenoh, args.timing != "lock-step")
                 for robot in robots]
        for robot, demo in zip(robots, demos):
            robot.demo_succeeded = demo.result()
    if args.keep_running and all(robot.demo_succeeded for robot in robots):
        print("hil up: demo done; running until Ctrl-C", flush=True)
        while not run.stop.is_set():
            run.wait(1.0)


def _held(config: SystemConfig) -> tuple[str, ...]:
    """The joints the demo holds where they are: on a floating base, those the robot stands
    on (every joint, where it does not stand: moving them would push it over the floor)."""
    if not config.floating_base:
        return ()
    found = stance(config.robot, dict(config.start_pose))
    return found.carrying if found else tuple(j.name for j in config.robot.movable_joints)


def _demo(robot: _Robot, run: Run, zenoh: ZenohSettings, real_time: bool) -> bool:
    """The robot's demo goal, followed to its end; whether it succeeded."""
    if real_time:
        # pacing the demo (MuJoCo's inverse dynamics along it) takes a CPU for a while just
        # as the goal starts: at normal priority it starved the real-time processes' Zenoh
        # threads, and 3 of 3 real-time pigot demos aborted on silent drives (under
        # SCHED_IDLE 3 of 3 succeeded); in lock-step nothing has a deadline, and an idle
        # thread beside two busy processes would hardly run
        enter_background()
    progress, say = robot.progress, f"hil up: {robot.label}"
    while progress.positions is None:          # the first samples tell where the joints are
        run.wait(0.05)
        if run.stop.is_set():
            return False
    with progress.lock:
        names, positions = progress.joint_names, progress.positions.copy()
    demo = paced_demo(robot.config.robot, names, positions, _held(robot.config))
    goal = demo.goal
    client = TrajectoryActionClient(session(zenoh), robot.name)
    try:
        duration = goal.points[-1].time_from_start
        slowed = (f", slowed {demo.slower:.2g}x to keep its motion within {MOTION_SHARE:.0%} of "
                  "the joints' effort limits" if demo.slower > 1 else "")
        print(f"{say}demo: {len(goal.points)} waypoints for {len(names)} joints over "
              f"{duration:.1f} s{slowed}", flush=True)
        for note in demo.notes:
            print(f"{say}warning: {note}", file=sys.stderr, flush=True)
        try:
            goal_id = client.send_goal(goal)
        except (GoalRejected, ControllerGone) as exc:
            print(f"{say}the demo goal was refused: {exc}", file=sys.stderr, flush=True)
            return False
        started = progress.control_time     # progress on the controller's clock (lock-step!)
        while True:
            try:
                result = client.wait_result(goal_id, 1.0)
                break
            except TimeoutError:
                pass
            except ControllerGone as exc:
                run.check()
                print(f"{say}{exc}", file=sys.stderr, flush=True)
                return False
            run.check()
            if run.stop.is_set():
                return False
            elapsed = progress.control_time - started
            print(f"  [{elapsed:6.1f} s]  {robot.label}demo "
                  f"{min(100, 100 * elapsed / duration):3.0f} %   {progress.line()}", flush=True)
        text = f" ({result.error_string})" if result.error_string else ""
        print(f"{say}demo {result.status.name.lower()}{text}", flush=True)
        return result.status is GoalStatus.SUCCEEDED
    finally:
        client.close()


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
