"""What ``hil up`` does once its processes run: wait out ``--duration``, or run each robot's
demo goal and follow it to its end."""

from __future__ import annotations

import sys
import time
from concurrent.futures import ThreadPoolExecutor

from hil.bus_config import SystemConfig
from hil.cli.run_progress import Progress
from hil.cli.up.robots import RobotRun
from hil.commissioning.demo_pace import MOTION_SHARE, paced_demo
from hil.commissioning.stance import stance
from hil.controllers import GoalRejected, GoalStatus
from hil.messaging.zenoh_api import ControllerGone, TrajectoryActionClient
from hil.realtime import Timing, enter_background
from hil.supervisor import Run
from hil.zenoh_session import ZenohSettings, session

#: the joints a demo holds (a standing robot's) are at rest below this speed (rad/s or m/s)
#: and waited for this long at most, on the controller's clock (s): a quadruped lands on its
#: feet within a second of its drives enabling (hil's own choice: no maker speaks to it)
REST_SPEED = 0.05
REST_WAIT = 3.0
#: ... and they stay so for this long first (controller's clock, s): at the first samples a
#: robot just off its brakes has not moved yet, and example-robot-data's G1 on Damiao
#: drives, its demo sent then, fell in 3 of 3 runs (sent 0.3 s or 2 s later, it stood:
#: docs/performance.md, "2026-12-06, issue 69: the MIT family's codec compiled, a Damiao
#: motor's registers read once")
REST_HOLD = 0.5


def supervise(args, robots: list[RobotRun], run: Run, zenoh: ZenohSettings) -> None:
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
        demos = [pool.submit(_demo, robot, run, zenoh, args.timing)
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


def _at_rest(progress: Progress, held: tuple[str, ...]) -> bool | None:
    """Whether the joints the demo holds (a standing robot's) stayed at rest in every cycle
    of the samples heard since the last call (None: none heard): held where the first
    samples found them, a quadruped still landing on its feet was held in mid-fall, and the
    demo pushed its base 2 cm over the floor (a lock-step run's first samples come at a
    moment the host's load decides)."""
    fastest = progress.take_fastest()
    if fastest is None:
        return None
    return all(fastest.get(name, 0.0) < REST_SPEED for name in held)


def _demo(robot: RobotRun, run: Run, zenoh: ZenohSettings, timing: Timing) -> bool:
    """The robot's demo goal, followed to its end; whether it succeeded."""
    if not timing.lock_step:
        # pacing the demo (MuJoCo's inverse dynamics along it) takes a CPU for a while just
        # as the goal starts: at normal priority it starved the real-time processes' Zenoh
        # threads, and 3 of 3 real-time pigot demos aborted on silent drives (under
        # SCHED_IDLE 3 of 3 succeeded); in lock-step nothing has a deadline, and an idle
        # thread beside two busy processes would hardly run
        enter_background()
    progress, say = robot.progress, f"hil up: {robot.label}"
    held = _held(robot.config)
    heard_at = None                            # the controller's clock at the first samples
    resting_since = None                       # ... since when the held joints are at rest
    while True:                                # the samples tell where the joints are
        run.wait(0.05)
        if run.stop.is_set():
            return False
        resting = _at_rest(progress, held)
        if resting is None:                    # nothing new heard
            continue
        now = progress.control_time
        heard_at = now if heard_at is None else heard_at
        resting_since = (now if resting_since is None else resting_since) if resting else None
        if resting_since is not None and (now - resting_since >= REST_HOLD or not held):
            break
        if now - heard_at > REST_WAIT:
            break                              # held where they are, moving or not
    with progress.lock:
        names, positions = progress.joint_names, progress.positions.copy()
    demo = paced_demo(robot.config.robot, names, positions, held)
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
        fallen = progress.fallen()     # joints that track lying on the floor: no success
        if fallen is not None:
            print(f"{say}demo failed: {fallen}", file=sys.stderr, flush=True)
        return result.status is GoalStatus.SUCCEEDED and fallen is None
    finally:
        client.close()
