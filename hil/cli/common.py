"""Options shared by several sub-commands."""

from __future__ import annotations

import argparse
import math
import os
import shutil
import signal
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path

from hil.can.capabilities import capabilities
from hil.can.zenoh_receipts import AWAIT_MONITOR
from hil.description import PackagePath
from hil.durations import parse_duration
from hil.errors import ProcessError, UsageError
from hil.bus_config.locate import config_path  # noqa: F401  (the commands call common.config_path)
from hil.realtime import LOCK_STEP, REAL_TIME
from hil.supervisor import parse_cpus
from hil.zenoh_security import Identity
from hil.zenoh_session import (DEFAULT_ENDPOINT, MEETING_VARIABLE, ZenohSettings, dials_peers,
                                key_name_problem, session, why_unreached)

#: how a loopback listener's endpoint reads (anything else is reachable from elsewhere)
LOOPBACK_HOSTS = ("/127.", "/[::1]", "/localhost:")


def positive(text: str) -> float:
    """An argparse type: a finite number > 0 (a time, a rate, a tolerance)."""
    return _finite(text, lambda value: value > 0, "a number > 0")


def non_negative(text: str) -> float:
    """An argparse type: a finite number >= 0 (0: off, where the option says so)."""
    return _finite(text, lambda value: value >= 0, "a number >= 0")


def duration(text: str) -> float:
    """An argparse type: a duration > 0 in seconds (hil.durations: ``2s``, ``500ms``)."""
    return _duration(text, lambda seconds: seconds > 0, "a duration > 0")


def duration_or_zero(text: str) -> float:
    """An argparse type: a duration >= 0 in seconds (0: off, where the option says so)."""
    return _duration(text, lambda seconds: seconds >= 0, "a duration >= 0")


def _duration(text: str, holds, what: str) -> float:
    try:
        seconds = parse_duration(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    if not holds(seconds):
        raise argparse.ArgumentTypeError(f"{text!r} is not {what}")
    return seconds


def _finite(text: str, holds, what: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or not holds(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not {what}")
    return value


def robot_name(name: str) -> str:
    """A robot's name as given on the command line, checked: UsageError where it cannot
    address one robot's keys (``**`` would address every robot's)."""
    problem = key_name_problem(name)
    if problem:
        raise UsageError.single(f"robot name {name!r}: {problem}",
                                hint="give one robot's name, e.g. ur3")
    return name


def add_package_path(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--package-path", action="append", default=[], metavar="DIR",
                        help="folder to search for $(find pkg) / package:// packages "
                             "(repeatable; before $HIL_PACKAGE_PATH and robots/)")


def package_path(args: argparse.Namespace) -> PackagePath:
    return PackagePath.from_environment(args.package_path)


def add_zenoh(parser: argparse.ArgumentParser, role: str) -> None:
    """The Zenoh options of a command whose process takes ``role`` under ``--secure``
    (hil.zenoh_security.ROLES)."""
    group = parser.add_argument_group(
        "Zenoh", f"without endpoints, the hil processes of this host meet at {DEFAULT_ENDPOINT} "
                 f"(${MEETING_VARIABLE} moves it): the first to start listens there, the others "
                 "connect to it, in any order (loopback only)")
    group.add_argument("--listen", action="append", default=[], metavar="ENDPOINT",
                       help="Zenoh endpoint to listen on, e.g. tcp/0.0.0.0:7450 (repeatable)")
    group.add_argument("--connect", action="append", default=[], metavar="ENDPOINT",
                       help="Zenoh endpoint of another hil process (repeatable)")
    group.add_argument("--zenoh-config", type=Path, metavar="FILE",
                       help="a Zenoh JSON5 config file (endpoints above still apply)")
    group.add_argument("--secure", type=Path, metavar="DIR",
                       help=f"mutual TLS with the keys of `hil keys init DIR`, as the {role} "
                            "role: TLS endpoints only, peers of that CA only, each role's rights "
                            "enforced (see `hil keys --help`)")
    parser.set_defaults(zenoh_role=role)


def zenoh_settings(args: argparse.Namespace) -> ZenohSettings:
    listen, connect = tuple(args.listen), tuple(args.connect)
    identity = Identity.of(args.secure, args.zenoh_role) if args.secure else None
    if not identity:
        _warn_if_exposed(listen)
    if not listen and not connect and args.zenoh_config is None:
        return ZenohSettings.meeting(identity)
    return ZenohSettings(listen, connect, args.zenoh_config, identity=identity)


def _warn_if_exposed(listen: tuple[str, ...]) -> None:
    """Say what a listener beyond loopback exposes without --secure."""
    exposed = [e for e in listen if not any(host in e for host in LOOPBACK_HOSTS)]
    if exposed:
        print(f"hil: warning: listening on {', '.join(exposed)} without --secure: anyone who "
              "reaches it can put CAN frames to the drives, send goals and reset faults "
              "(see `hil keys --help`)", file=sys.stderr)


#: how long a starting sim or controller looks for its peers before asking who runs (s),
#: and how long the set of them must stay the same
PEER_WAIT = 2.0
PEER_SETTLE = 0.3


def tokens(zenoh: ZenohSettings, key_expr: str, timeout: float = PEER_WAIT) -> list[str]:
    """The liveliness tokens under ``key_expr`` that the hil processes reachable now hold,
    once this process has met them: the first peer (the meeting point's), then those its
    gossip names, until no new one came for PEER_SETTLE (a token is heard from the peer
    that holds it, not relayed)."""
    opened = session(zenoh)
    start = settled = time.monotonic()
    peers = 0
    while dials_peers(zenoh) and time.monotonic() < start + PEER_WAIT and (
            not peers or time.monotonic() < settled + PEER_SETTLE):
        now_peers = len(list(opened.info.peers_zid()))
        if now_peers != peers:
            peers, settled = now_peers, time.monotonic()
        time.sleep(0.02)
    return sorted(str(reply.ok.key_expr) for reply in
                  opened.liveliness().get(key_expr, timeout=timeout) if reply.ok)


def refuse_a_second(zenoh: ZenohSettings, robot: str, process: str) -> None:
    """ProcessError if a ``hil <process>`` for ``robot`` already runs on this Zenoh network: two
    simulators would both answer every frame (two nodes of one id on a CAN bus), two
    controllers would both command the drives. With no endpoints every process of the host
    meets every other, so a forgotten one in another terminal is found here."""
    found = tokens(zenoh, f"hil/{robot}/{process}")
    if found:
        raise ProcessError.single(
            f"a hil {process} for robot '{robot}' already runs on this Zenoh network",
            hint=f"stop that one first, or give this one a network of its own (--listen and "
                 f"--connect, or ${MEETING_VARIABLE})")


def no_controller(zenoh: ZenohSettings, robot: str) -> ProcessError:
    """The error for a client whose robot's ``hil control`` never answered, with why where
    the session reached nobody at all (``why_unreached``)."""
    what = f"no hil control for robot '{robot}' is reachable"
    why = why_unreached(zenoh)
    return ProcessError.single(f"{what}: {why}" if why else what,
                               hint="start `hil control CONFIG` (or check --connect)")


def add_ros(parser: argparse.ArgumentParser, what: str) -> None:
    """``--ros`` and its settings (hil.messaging.ros.face.RosSettings)."""
    group = parser.add_argument_group(
        "ROS 2", "appear in a ROS 2 graph on rmw_zenoh (a client of the Zenoh router "
                 "that ROS uses: rmw_zenohd, or `hil router`)")
    group.add_argument("--ros", action="store_true", help=what)
    group.add_argument("--ros-domain-id", type=int, metavar="N",
                       help="ROS domain id (default: ROS_DOMAIN_ID, else 0)")
    group.add_argument("--ros-namespace", metavar="NS", help="ROS namespace (default /)")
    group.add_argument("--ros-distro", metavar="NAME",
                       help="ROS 2 distribution whose type hashes to use (jazzy, kilted, "
                            "lyrical; default jazzy)")
    group.add_argument("--ros-router", metavar="ENDPOINT",
                       help="the Zenoh router's endpoint (default tcp/localhost:7447, "
                            "rmw_zenohd's)")


def ros_settings(args: argparse.Namespace):
    """The RosSettings asked for, or None without ``--ros``."""
    if not args.ros:
        return None
    from hil.messaging.ros.face import RosSettings     # noqa: PLC0415 (only with --ros)
    try:
        return RosSettings.from_environment(args.ros_domain_id, args.ros_namespace,
                                            args.ros_distro, args.ros_router)
    except ValueError as exc:
        raise UsageError.single(f"--ros: {exc}", hint="see hil COMMAND --help, group ROS 2"
                                ) from None


@contextmanager
def ros_node(settings, name: str, serving: str, timeout: float, hint: str):
    """A ROS 2 node ``name`` for a command-line client, once the service ``serving`` (fully
    qualified) has a server in the graph; ProcessError with ``hint`` if none within
    ``timeout``. Closed, with its session, on exit."""
    from hil.messaging.ros.face import open_context            # noqa: PLC0415 (only with --ros)
    from hil.messaging.ros.rmw_zenoh import EntityKind         # noqa: PLC0415
    context = open_context(settings)
    node = context.node(name, settings.namespace)
    try:
        if not context.wait_for(EntityKind.SERVICE, serving, timeout):
            raise ProcessError.single(f"no server of {serving} on ROS domain "
                                      f"{settings.domain_id} via {settings.router}", hint=hint)
        yield node
    finally:
        node.close()
        context.session.close()


def ros_options(args: argparse.Namespace) -> list[str]:
    """The ``--ros`` options given, for a child process (none without ``--ros``)."""
    if not args.ros:
        return []
    given = {"--ros-domain-id": args.ros_domain_id, "--ros-namespace": args.ros_namespace,
             "--ros-distro": args.ros_distro, "--ros-router": args.ros_router}
    return ["--ros", *(f"{option}={value}" for option, value in given.items()
                       if value is not None)]


def add_can_override(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--interface", metavar="NAME",
                        help="python-can interface for every bus instead of the config's "
                             "(e.g. socketcan, zenoh, virtual)")
    parser.add_argument("--channel", action="append", default=[], metavar="BUS=CHANNEL",
                        help="channel for one bus instead of the config's, e.g. arm=vcan0")


def can_overrides(args: argparse.Namespace) -> tuple[str | None, dict[str, str]]:
    channels = {}
    for item in args.channel:
        bus, sep, channel = item.partition("=")
        if not sep or not bus or not channel:
            raise UsageError.single(f"--channel '{item}' is not BUS=CHANNEL",
                                    hint="e.g. --channel arm=vcan0")
        channels[bus] = channel
    return args.interface, channels


def bus_report(buses: dict, channel_numbers: dict[str, int] | None = None) -> list[str]:
    """One line per bus with its frame counters (where its interface keeps them: zenoh), and
    its channel number in the CAN log where the log numbers them."""
    lines = []
    for name, bus in buses.items():
        counters = capabilities(bus).counters
        number = (channel_numbers or {}).get(name)
        label = f"bus {name}" + (f" (log channel {number})" if number else "")
        if counters is not None:
            lines.append(f"{label}: {counters}")
        elif number:
            lines.append(label)
    return lines


def add_timing(parser: argparse.ArgumentParser, lock_step_help: str) -> None:
    """``--lock-step`` and ``--real-time`` (the default), as ``args.timing``, a Timing."""
    timing = parser.add_mutually_exclusive_group()
    timing.add_argument("--lock-step", dest="timing", action="store_const", const=LOCK_STEP,
                        help=lock_step_help)
    timing.add_argument("--real-time", dest="timing", action="store_const", const=REAL_TIME,
                        help="on the wall clock (the default)")
    parser.set_defaults(timing=REAL_TIME)


def add_cpus(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--cpus", metavar="LIST",
                        help="run on these CPUs only, e.g. 1 or 2,3 (default: any; hil up "
                             "gives sim and controller a CPU each in real time, one CPU "
                             "together in lock-step)")


def add_await_monitor(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--await-monitor", action="store_true",
                        help="open the Zenoh CAN buses only once a CAN monitor (hil viz) hears "
                             f"them, waiting up to {AWAIT_MONITOR:g} s: its log then holds "
                             "this process' frames from the first (hil up --lock-step asks it)")


def announce_await_monitor(args: argparse.Namespace, command: str) -> None:
    """With --await-monitor, say what the process waits for before its banner."""
    if args.await_monitor:
        print(f"hil {command}: waiting for a CAN monitor (hil viz) to hear the buses, up to "
              f"{AWAIT_MONITOR:g} s (--await-monitor)", flush=True)


def keep_on_cpus(args: argparse.Namespace) -> None:
    """Keep this process (and the threads it starts after) on the CPUs of --cpus, if given,
    at its scheduling as it is (lock-step, and the visualiser)."""
    chosen = cpus(args)
    if chosen:
        os.sched_setaffinity(0, chosen)


def cpus(args: argparse.Namespace) -> set[int] | None:
    """The CPUs of --cpus, or None."""
    if not args.cpus:
        return None
    try:
        chosen = parse_cpus(args.cpus)
    except ValueError:
        raise UsageError.single(f"--cpus '{args.cpus}' is not a list of CPU numbers",
                                hint="e.g. --cpus 1 or --cpus 2,3") from None
    usable = os.sched_getaffinity(0)
    if not chosen <= usable:
        raise UsageError.single(f"--cpus {args.cpus}: this process may use CPUs "
                                f"{','.join(map(str, sorted(usable)))} only")
    return chosen


def display_available() -> bool:
    """Whether a rerun viewer could open a window here."""
    has_display = sys.platform == "darwin" or bool(os.environ.get("DISPLAY")
                                                   or os.environ.get("WAYLAND_DISPLAY"))
    return has_display and shutil.which("rerun") is not None


def on_stop_signals(stop) -> dict:
    """Make SIGINT and SIGTERM call ``stop()``; the handlers they had (to restore).

    ``stop`` runs in a thread of its own: a handler runs in the main thread between two
    bytecodes, possibly while that thread holds the lock of the very Event ``stop`` sets
    (Event.wait re-acquires it on each wake-up), and the set would then wait for it forever
    (`hil sim` hung on a SIGTERM in a CI run of 2026-11-27)."""
    def handler(signum, frame) -> None:
        threading.Thread(target=stop, name="stop-signal", daemon=True).start()
    return {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}

