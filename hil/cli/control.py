"""``hil control CONFIG``: the controller process (CAN master + controllers + Zenoh)."""

from __future__ import annotations

import argparse
import dataclasses
import gc
import json
import select
import signal
import sys
from pathlib import Path

from hil.bus_config import load_bus_config, open_buses
from hil.bus_config.locate import shipped_names
from hil.can.capabilities import capabilities
from hil.cli import common
from hil.control_node import ControlNode
from hil.controllers.config import DEFAULT_GOAL_TOLERANCE, controllers_for
from hil.errors import UsageError
from hil.hardware import LOCK_STEP_REPLY_TIMEOUT, CanHardwareInterface, FakeHardwareInterface
from hil.messaging.keys import IMU, WRENCH, sensor_key
from hil.messaging.zenoh_api import key
from hil.realtime import REAL_TIME_PRIORITY, enter_real_time
from hil.realtime.stalls import BENCH_STALL_STATUS
from hil.zenoh_session import close_all, session


#: how long ``hil control`` waits for its drives by default (s): long enough to start the
#: sim in another terminal after it
CONTROL_BOOT_TIMEOUT = 60.0


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.epilog = (
        "exit status: 0 stopped (Ctrl-C, SIGTERM), the drives disabled; 1 an error (the "
        "message names the drive that did not come up, or the input at fault); "
        f"{BENCH_STALL_STATUS} in real time, the bring-up failed while the bench itself "
        "stalled (the simulator, the Zenoh transport or this process did not run; the "
        "message names the stalls): the bench broke real time, the drive need not have failed")
    parser.add_argument("config", help="bus config, e.g. bus_config/ur3.yaml, or a robot's "
                                       f"name ({shipped_names()})")
    parser.add_argument("--fake", action="store_true",
                        help="no CAN, no physics: echo the commands as the measured state")
    common.add_timing(parser, "run each cycle as soon as the drives answered (with hil sim "
                              "--lock-step); the controller clock advances one period per cycle")
    parser.add_argument("--joint-state-rate", type=common.positive, default=100.0, metavar="HZ",
                        help="joint state publication rate (default 100)")
    parser.add_argument("--priority", type=int, default=REAL_TIME_PRIORITY, metavar="N",
                        help="real time: run the control loop under SCHED_FIFO priority N "
                             f"where the OS allows it (default {REAL_TIME_PRIORITY}; 0: the "
                             "normal scheduler)")
    parser.add_argument("--goal-tolerance", type=common.positive, default=None, metavar="RAD",
                        help="hil's own controllers: how far (rad or m) each joint may end "
                             f"from a goal (default {DEFAULT_GOAL_TOLERANCE:g})")
    parser.add_argument("--controllers", type=Path, metavar="YAML",
                        help="run the controllers of your controller_manager YAML (a "
                             "ros2_controllers.yaml) instead of hil's own; the bus config's "
                             "controllers: entry maps its names (docs/controllers.md)")
    parser.add_argument("--boot-timeout", type=common.duration, default=CONTROL_BOOT_TIMEOUT,
                        metavar="TIME",
                        help="how long to wait for every drive to boot (default "
                             f"{CONTROL_BOOT_TIMEOUT:g}: start hil sim before or after)")
    parser.add_argument("--hold", action="store_true",
                        help="started, wait before bringing up the drives until a line or the "
                             "end of standard input (hil up starts several robots' "
                             "controllers so, that no loop runs while another process starts)")
    parser.add_argument("--report", type=Path, metavar="FILE.json",
                        help="at exit, write the run's figures (periods, busy times, round "
                             "trips, faults, frame counts) as JSON")
    common.add_cpus(parser)
    common.add_await_monitor(parser)
    common.add_can_override(parser)
    common.add_package_path(parser)
    common.add_zenoh(parser, "controller")
    common.add_ros(parser, "also be a ROS 2 node (hil_control): joint_states, the "
                           "FollowJointTrajectory action at joint_trajectory_controller/"
                           "follow_joint_trajectory, diagnostics, robot_description")
    parser.add_argument("--ros-use-sim-time", action="store_true",
                        help="with --ros: stamp joint states, feedback and diagnostics on the "
                             "plant's time (what hil sim --ros publishes as /clock), as "
                             "use_sim_time nodes expect")


def run(args: argparse.Namespace) -> int:
    config = load_bus_config(common.config_path(args.config), common.package_path(args))
    controllers = controllers_for(config, args.goal_tolerance, args.controllers)
    for warning in controllers.warnings:
        print(f"hil control: {warning}", file=sys.stderr)
    zenoh = common.zenoh_settings(args)
    if args.timing.lock_step:
        common.keep_on_cpus(args)
    else:                          # the frame handling just below the loop (its own priority)
        enter_real_time(max(0, args.priority - 1), common.cpus(args))
    # after the scheduling: Zenoh's runtime threads, started with the session, inherit it
    common.refuse_a_second(zenoh, config.robot.name, "control")
    buses = {}
    if args.fake:
        hardware = FakeHardwareInterface(config.robot)
    else:
        interface, channels = common.can_overrides(args)
        common.announce_await_monitor(args, "control")
        buses = open_buses(config, zenoh, interface, channels, lossless=args.timing.lock_step,
                           await_monitor=args.await_monitor)
        hardware = CanHardwareInterface(
            config, buses, reply_timeout=LOCK_STEP_REPLY_TIMEOUT if args.timing.lock_step else None,
            boot_timeout=args.boot_timeout)
    try:
        node = ControlNode(hardware, session(zenoh), config.cycle_hz,
                           args.timing, joint_state_hz=args.joint_state_rate,
                           controllers=controllers,
                           priority=args.priority, faces=_ros_faces(args, config))
    except BaseException:        # e.g. no Zenoh router for --ros: no bus may keep us alive
        for bus in buses.values():
            bus.shutdown()
        close_all()
        raise
    previous = common.on_stop_signals(node.stop)
    mode = "fake hardware" if args.fake else f"{len(config.drives)} drive(s)"
    print(f"hil control: {config.robot.name}, {mode}, {config.cycle_hz:g} Hz, "
          f"{args.timing}; goals on "
          f"hil/{config.robot.name}/follow_joint_trajectory; controllers: "
          f"{controllers.summary()}", flush=True)
    if not args.fake:
        _announce_sensors(args, config)
    gc.collect()
    gc.freeze()     # start-up's objects out of the collector's way: shorter passes in the loop
    try:
        if args.hold:
            _hold(zenoh, config.robot.name, node)
        if not node.stopping:
            node.run()
    finally:
        for bus in buses.values():
            bus.shutdown()
        close_all()
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    for fault in node.faults:
        print(f"hil control: fault: {fault}", file=sys.stderr)
    print(f"hil control: {node.summary()}")
    if args.report is not None:
        args.report.write_text(json.dumps({**node.figures(), "buses": {
            name: dataclasses.asdict(capabilities(bus).counters) for name, bus in buses.items()
            if capabilities(bus).counters is not None}}, indent=2))
    for line in common.bus_report(buses):
        print(f"hil control: {line}")
    print("hil control: stopped; drives disabled", flush=True)
    return 0


def _hold(zenoh, robot: str, node: ControlNode) -> None:
    """--hold: say so (a liveliness token ``hil/<robot>/control/held``), then wait until
    standard input has a line or ends, or ``node`` is told to stop."""
    token = session(zenoh).liveliness().declare_token(key(robot, "control/held"))
    try:
        while not node.stopping:
            if select.select([sys.stdin], [], [], 0.1)[0]:
                return
    finally:
        token.undeclare()


def _announce_sensors(args: argparse.Namespace, config) -> None:
    """Where each sensor is read and where its samples go."""
    read = [(sensor, IMU, f"IMU '{sensor.name}' "
             + (f"read off {sensor.port}" if sensor.bus is None
                else f"polled at {sensor.poll_hz:g} Hz on bus '{sensor.bus}'"
                if sensor.poll_hz is not None else f"read off bus '{sensor.bus}'"))
            for sensor in config.imus]
    read += [(sensor, WRENCH, f"force-torque sensor '{sensor.name}' polled at "
              f"{sensor.poll_hz:g} Hz on bus '{sensor.bus}'") for sensor in config.force_torques]
    for sensor, kind, what in read:
        ros = ""
        if args.ros:
            from hil.messaging.ros.face import sensor_topic     # noqa: PLC0415 (--ros only)
            ros = f" and the ROS topic {sensor_topic(sensor.name, kind)}"
        print(f"hil control: {what}, its samples on "
              f"hil/{config.robot.name}/{sensor_key(sensor.name, kind)}{ros}", flush=True)


def _ros_faces(args: argparse.Namespace, config) -> list:
    """The factory of the controller's ROS 2 face in a list; none without --ros."""
    settings = common.ros_settings(args)
    if settings is None:
        if args.ros_use_sim_time:
            raise UsageError.single("--ros-use-sim-time is for the ROS 2 face",
                                    hint="add --ros")
        return []
    from hil.messaging.ros.face import ACTION, PlantClock, RosControlFace  # noqa: PLC0415
    from hil.visualisation.urdf_export import viewer_urdf            # noqa: PLC0415

    def make(node: ControlNode):
        plant_clock = (PlantClock(session(common.zenoh_settings(args)), config.robot.name)
                       if args.ros_use_sim_time else None)
        face = RosControlFace(settings, node.controller, node.clock,
                              viewer_urdf(config.robot).decode(), node.reset_faults,
                              plant_clock, facts={
                                  "robot": config.robot.name, "cycle_hz": float(config.cycle_hz),
                                  "lock_step": args.timing.lock_step,
                                  "fake_hardware": bool(args.fake)}, manager=node.manager)
        action = f"{settings.namespace.rstrip('/')}/{node.controller.name}/{ACTION}"
        print(f"hil control: ROS 2 node {settings.namespace.rstrip('/')}/hil_control on "
              f"domain {settings.domain_id} via {settings.router} ({settings.distro}); "
              f"action {action}; stamps on the "
              f"{'plant' if args.ros_use_sim_time else 'wall'} clock", flush=True)
        return face
    return [make]
