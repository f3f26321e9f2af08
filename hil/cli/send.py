"""``hil send ROBOT``: send a trajectory goal, print feedback and the result."""

from __future__ import annotations

import argparse
import json
import math
import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from hil.cli import common
from hil.controllers import (
    HARDWARE_FAULT, GoalRejected, GoalResult, GoalStatus, JointTolerance, TrajectoryGoal,
    TrajectoryPoint,
)
from hil.errors import ConfigError, UsageError
from hil.input_files import read_input_file
from hil.messaging.zenoh_api import ControllerGone, TrajectoryActionClient, WaitStopped
from hil.zenoh_session import close_all, session

# PyYAML's C loader where it was built with libyaml, its pure-Python one elsewhere
_YAML_LOADER = getattr(yaml, "CSafeLoader", yaml.SafeLoader)

#: s a stopped client waits for the result of a goal that ended before its cancel arrived
#: (published as it ended: normally already here)
ENDED_RESULT_WAIT = 2.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("target", nargs="*", metavar="ROBOT [FILE]",
                        help="robot name (e.g. ur3; none with --ros), then optionally a "
                             "trajectory as "
                             "YAML/JSON: joint_names, points (positions, velocities, "
                             "accelerations, time_from_start), optional path_tolerance / "
                             "goal_tolerance {joint: rad}, goal_time_tolerance")
    parser.add_argument("--joint", action="append", default=[], help="joint to move (short form)")
    parser.add_argument("--to", action="append", type=float, default=[], metavar="POSITION",
                        help="its target position at the joint, in rad (revolute) or m "
                             "(prismatic), one per --joint")
    parser.add_argument("--in", dest="duration", type=common.duration, default=2.0,
                        metavar="TIME", help="time to get there, e.g. 2s, 500ms (default 2s)")
    parser.add_argument("--timeout", type=common.duration, default=60.0, metavar="TIME",
                        help="how long to wait for the result, e.g. 60s (default 60s)")
    parser.add_argument("--quiet", action="store_true", help="print the result only")
    common.add_zenoh(parser, "operator")
    common.add_ros(parser, "send to a FollowJointTrajectory action server on ROS 2 "
                           "(rmw_zenoh): hil control --ros, or a ros2_control "
                           "joint_trajectory_controller")
    parser.add_argument("--action", default=None, metavar="NAME",
                        help="with --ros: the action (default joint_trajectory_controller/"
                             "follow_joint_trajectory, in --ros-namespace)")


def run(args: argparse.Namespace) -> int:
    settings = common.ros_settings(args)
    if settings is not None:
        if len(args.target) > 1 or (args.target and not _is_trajectory_file(args.target[0])):
            raise UsageError.single(f"with --ros, give no robot name: {' '.join(args.target)}",
                                    hint="hil send --ros [FILE] [--joint NAME --to POS ...] "
                                         "[--action NAME]")
        args.file = Path(args.target[0]) if args.target else None
        return _send_ros(args, settings, _goal(args))
    if not args.target or len(args.target) > 2:
        raise UsageError.single("give a robot name, then optionally a trajectory file"
                                if not args.target else
                                f"too many arguments: {' '.join(args.target[2:])}",
                                hint="hil send ROBOT [FILE] [--joint NAME --to POS ...]")
    args.robot = common.robot_name(args.target[0])
    args.file = Path(args.target[1]) if len(args.target) == 2 else None
    goal = _goal(args)
    zenoh = common.zenoh_settings(args)
    client = TrajectoryActionClient(session(zenoh), args.robot)
    try:
        if not client.wait_for_controller(15.0):
            raise common.no_controller(zenoh, args.robot)
        return _follow(client, goal, args, (GoalRejected, ControllerGone, TimeoutError))
    finally:
        client.close()
        close_all()


def _feedback_printer(args: argparse.Namespace):
    """Prints every fifth feedback's position errors (none with --quiet)."""
    shown = [0]

    def show(feedback):
        shown[0] += 1
        if not args.quiet and shown[0] % 5 == 1:
            errors = " ".join(f"{n}={e:+.4f}" for n, e in zip(feedback.joint_names,
                                                               feedback.error.positions))
            print(f"  error {errors}", flush=True)
    return show


def _follow(client, goal: TrajectoryGoal, args: argparse.Namespace,
            failures: tuple[type[Exception], ...], by: str = "") -> int:
    """Send ``goal`` through ``client``, print its feedback and result; the exit status
    (1 for a goal that did not succeed or for one of ``failures``, 128 + the signal for a
    client stopped by SIGINT or SIGTERM, its goal cancelled)."""
    try:
        goal_id = client.send_goal(goal)
        print(f"hil send: goal {goal_id[:8]} accepted{by}", flush=True)
        with _stop_signals_noted() as stop:
            try:
                result = client.wait_result(goal_id, args.timeout, _feedback_printer(args),
                                            stop=stop.asked)
            except WaitStopped:
                _cancel(client, goal_id, failures, "stopped")
                return 128 + stop.signum
            except failures as exc:
                if not isinstance(exc, ControllerGone):      # else no one runs it any more
                    _cancel(client, goal_id, failures, "no result")
                raise
    except failures as exc:
        print(f"hil send: {exc}", file=sys.stderr)
        _hint_after_a_fault(exc.error_code if isinstance(exc, GoalRejected) else None, args)
        return 1
    print(f"hil send: {_described(result)}")
    _hint_after_a_fault(result.error_code, args)
    return 0 if result.status is GoalStatus.SUCCEEDED else 1


@dataclass
class StopRequest:
    """SIGINT or SIGTERM heard while a goal runs: which (``signum``), and ``asked``, set."""
    asked: threading.Event = field(default_factory=threading.Event)
    signum: int = 0

    def note(self, signum: int, frame) -> None:
        self.signum = self.signum or signum      # a second signal changes nothing: the
        self.asked.set()                         # cancel is bounded (its query's timeout)


@contextmanager
def _stop_signals_noted() -> Iterator[StopRequest]:
    """A block in which SIGINT and SIGTERM are noted, not raised: stopped either way, the
    client cancels its goal (SIGTERM's default action would end it without, SIGINT's
    KeyboardInterrupt).

    Noted, because an exception raised by a signal handler lands wherever the main thread
    is: once inside a queue's lock that Zenoh's receiving thread needs for the next
    feedback, and that thread, blocked, delivered nothing more, the cancel's reply included
    (a CI run: "not cancelled", then "close operation timed out"). SIGINT's handler is set
    here too, and both unblocked: a process started with SIGINT ignored (a shell's background
    job; a parent that ignored it, as a test run's worker did) ran its goal to the end."""
    stop = StopRequest()
    if threading.current_thread() is not threading.main_thread():
        yield stop              # only the main thread may set a handler (run in a thread)
        return
    before = {signum: signal.signal(signum, stop.note)
              for signum in (signal.SIGINT, signal.SIGTERM)}
    blocked = signal.pthread_sigmask(signal.SIG_UNBLOCK, set(before))
    try:
        yield stop
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
        for signum, handler in before.items():
            signal.signal(signum, handler)


def _cancel(client, goal_id: str, failures: tuple[type[Exception], ...], why: str) -> None:
    """A client that stops mid-goal (``why``: stopped by a signal, or given up waiting) asks
    for the goal to be cancelled and says so, as ``ros2 action send_goal`` does in its
    ``finally`` for a goal still accepted or executing (ros2cli,
    ros2action/verb/send_goal.py: "Canceling goal...", then "Goal canceled."): else the
    controller moves the arm on to its target after the client is gone."""
    print(f"hil send: {why}: cancelling goal {goal_id[:8]}", file=sys.stderr, flush=True)
    try:
        cancelled = client.cancel(goal_id)
    except failures as exc:
        print(f"hil send: goal {goal_id[:8]} not cancelled: {exc}", file=sys.stderr)
        return
    if cancelled:
        print(f"hil send: goal {goal_id[:8]} canceled", file=sys.stderr)
        return
    # the goal ended before the cancel reached it: its result is on its way, or here
    try:
        ended = client.wait_result(goal_id, ENDED_RESULT_WAIT)
    except failures:
        ended = None
    print(f"hil send: goal {goal_id[:8]} not cancelled: the controller no longer runs it ("
          + (f"it had ended {_described(ended)}" if ended is not None else
             f"no result heard within {ENDED_RESULT_WAIT:g} s") + ")", file=sys.stderr)


def _described(result: GoalResult) -> str:
    """A goal's result in words: ``aborted, error_code -4 (why)``."""
    text = f" ({result.error_string})" if result.error_string else ""
    return f"{result.status.name.lower()}, error_code {result.error_code}{text}"


def _hint_after_a_fault(error_code: int | None, args: argparse.Namespace) -> None:
    """After a drive fault: what to do next (the controller refuses goals until a reset)."""
    if error_code == HARDWARE_FAULT:
        reset = "hil reset --ros" if args.ros else f"hil reset {args.robot}"
        print(f"hil send: what to do: `{reset}` clears the drives' faults, then send "
              "again; a bench fault on a loaded host (hil up exit 3) is real time missed: CI "
              "runs --lock-step (docs/real-time.md)", file=sys.stderr)


def _is_trajectory_file(text: str) -> bool:
    return Path(text).suffix in (".yaml", ".yml", ".json") or Path(text).is_file()


def _send_ros(args: argparse.Namespace, settings, goal: TrajectoryGoal) -> int:
    """Send ``goal`` to a ROS 2 FollowJointTrajectory server and wait for its result."""
    from hil.messaging.ros.action import RosTrajectoryActionClient       # noqa: PLC0415
    from hil.messaging.ros.face import ACTION_NAME                       # noqa: PLC0415
    from hil.messaging.ros.interfaces import FollowJointTrajectory, TypeHashes  # noqa: PLC0415
    from hil.messaging.ros.node import ServiceError                     # noqa: PLC0415
    from hil.messaging.ros.rmw_zenoh import fully_qualified              # noqa: PLC0415
    action = fully_qualified(settings.namespace, args.action or ACTION_NAME)
    with common.ros_node(settings, "hil_send", f"{action}/_action/send_goal", 15.0,
                         hint="start `hil control CONFIG --ros` (or check --action, "
                              "--ros-domain-id, --ros-distro)") as node:
        client = RosTrajectoryActionClient(node, action, FollowJointTrajectory.for_distro(
            TypeHashes(settings.distro)))
        return _follow(client, goal, args, (GoalRejected, ServiceError), f" by {action}")


def _goal(args: argparse.Namespace) -> TrajectoryGoal:
    if args.file is not None:
        return goal_from_file(args.file)
    if not args.joint or len(args.joint) != len(args.to):
        raise UsageError.single("give a trajectory file, or --joint NAME --to POSITION pairs",
                                hint="e.g. hil send ur3 --joint joint2 --to 0.5 --in 2s")
    return TrajectoryGoal(tuple(args.joint), (TrajectoryPoint(args.duration, tuple(args.to)),))


def goal_from_file(path: Path) -> TrajectoryGoal:
    """Read a trajectory file (YAML or JSON), with errors naming the file."""
    text = read_input_file(path, "trajectory", hint="give a YAML or JSON trajectory file",
                           syntax="json" if path.suffix == ".json" else "yaml")
    try:
        # libyaml's loader where PyYAML has it: a 10,000-point goal parses in a fraction
        data = (yaml.load(text, Loader=_YAML_LOADER) if path.suffix != ".json"
                else json.loads(text))
        names = tuple(data["joint_names"])
        points = tuple(TrajectoryPoint(float(p["time_from_start"]),
                                       tuple(float(x) for x in p["positions"]),
                                       tuple(float(x) for x in p.get("velocities", ())),
                                       tuple(float(x) for x in p.get("accelerations", ())))
                       for p in data["points"])
        tolerance = lambda key: tuple(JointTolerance(j, float(v))  # noqa: E731
                                      for j, v in (data.get(key) or {}).items())
        goal = TrajectoryGoal(names, points, None, tolerance("path_tolerance"),
                              tolerance("goal_tolerance"),
                              float(data.get("goal_time_tolerance", 0.0)))
    except (yaml.YAMLError, json.JSONDecodeError, KeyError, TypeError, ValueError,
            AttributeError, OverflowError, RecursionError) as exc:   # what bad data raises
        raise ConfigError.single(f"'{path}' is not a trajectory: {exc!r}", path,
                                 hint="needs joint_names and points with positions and "
                                      "time_from_start") from None
    _check_numbers(goal, path)
    return goal


def _check_numbers(goal: TrajectoryGoal, path: Path) -> None:
    """What a FollowJointTrajectory message cannot carry, named before anything is sent (the
    controller checks the rest: joints, limits, order of times)."""
    durations = [(f"point {p} time_from_start", point.time_from_start)
                 for p, point in enumerate(goal.points)]
    durations.append(("goal_time_tolerance", goal.goal_time_tolerance))
    for what, seconds in durations:
        if not math.isfinite(seconds) or not 0 <= seconds < 2**31:
            raise ConfigError.single(f"{what} is {seconds}: not a duration", path,
                                     hint="give seconds as a finite number from 0 (below 2^31)")
    for key, tolerances in (("path_tolerance", goal.path_tolerance),
                            ("goal_tolerance", goal.goal_tolerance)):
        for tolerance in tolerances:
            if not math.isfinite(tolerance.position):
                raise ConfigError.single(f"{key} of joint '{tolerance.name}' is "
                                         f"{tolerance.position}", path,
                                         hint="give radians (0: the controller's default, "
                                              "< 0: not checked)")
