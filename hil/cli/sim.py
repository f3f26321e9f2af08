"""``hil sim CONFIG``: the MuJoCo plant and every virtual drive of a bus config."""

from __future__ import annotations

import argparse
import gc
import signal
import sys
import threading
import time

import numpy as np

from hil.bus_config import load_bus_config, open_buses
from hil.bus_config.locate import shipped_names
from hil.cli import common
from hil.cli.describe import sensor_line
from hil.can import watch_deliveries
from hil.simulator import Simulator
from hil.can.faults import (
    DriveFault, FrameFault, ProcessFault, SensorFault, parse_fault, with_frame_faults,
)
from hil.drives import Power
from hil.errors import HilError
from hil.messaging.scene import SceneState
from hil.messaging.zenoh_api import ScenePublisher, SimClockPublisher, StallPublisher
from hil.protocols import protocol
from hil.realtime import IO_PRIORITY, enter_real_time, enter_side_work
from hil.zenoh_session import close_all, session

CLOCK_PERIOD = 0.05
#: an injected drive fault waits for its moment of the plant's time looking this often (s)
INJECT_POLL = 0.005
#: how often /clock is published with --ros (s of wall time): rclcpp's time source moves in
#: these steps
ROS_CLOCK_PERIOD = 0.01


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("config", help="bus config, e.g. bus_config/ur3.yaml, or a robot's "
                                       f"name ({shipped_names()})")
    common.add_timing(parser, "advance the plant one control period per SYNC (reproducible, "
                              "as fast as the controller) instead of following the wall clock")
    parser.add_argument("--duration", type=common.duration, metavar="TIME",
                        help="stop after TIME of plant time, e.g. 30s, 2min")
    parser.add_argument("--status-period", type=common.duration_or_zero, default=2.0,
                        metavar="TIME", help="print the status every TIME (0: never; default 2s)")
    parser.add_argument("--fault", action="append", default=[], metavar="SPEC",
                        help="inject a fault (repeatable): drop:BUS:FRACTION, "
                             "delay:BUS:FRACTION:MS, corrupt:BUS:FRACTION, silence:BUS/NODE@S, "
                             "restart:BUS/NODE@S, fault:BUS/NODE@S (S: seconds of the plant's "
                             "time after every drive is enabled); silence|freeze|spike:SENSOR@S "
                             "(S: seconds of the plant's time)")
    parser.add_argument("--fault-seed", type=int, default=0, metavar="N",
                        help="seed of the fault injector's random choices (default 0)")
    parser.add_argument("--priority", type=int, default=IO_PRIORITY, metavar="N",
                        help="real time: run every thread under SCHED_FIFO priority N where "
                             f"the OS allows it (default {IO_PRIORITY}; 0: the normal "
                             "scheduler)")
    common.add_cpus(parser)
    common.add_await_monitor(parser)
    common.add_can_override(parser)
    common.add_package_path(parser)
    common.add_zenoh(parser, "drives")
    common.add_ros(parser, "also be a ROS 2 node (hil_sim) publishing /clock from the "
                           f"plant's time every {ROS_CLOCK_PERIOD * 1000:g} ms, for "
                           "use_sim_time nodes")


def run(args: argparse.Namespace) -> int:
    config = load_bus_config(common.config_path(args.config), common.package_path(args))
    for warning in config.warnings:
        print(warning, file=sys.stderr)
    zenoh = common.zenoh_settings(args)
    frame_faults, drive_faults, sensor_faults = _faults(args, config)
    if args.timing.lock_step:
        common.keep_on_cpus(args)
    scheduling = ("lock-step" if args.timing.lock_step
                  else enter_real_time(args.priority, common.cpus(args)))
    # after the scheduling: Zenoh's runtime threads, started with the session, inherit it
    common.refuse_a_second(zenoh, config.robot.name, "sim")
    simulator, buses, ros_clock = _open(args, config, zenoh, frame_faults)
    for fault in sensor_faults:
        simulator.sensor(fault.sensor).inject(fault.kind, fault.at)
        print(f"hil sim: sensor '{fault.sensor}' will {fault.kind.value} at {fault.at:g} s of "
              "the plant's time", flush=True)
    token = None
    stop = threading.Event()

    def on_signal():
        stop.set()
        simulator.stop()

    previous = common.on_stop_signals(on_signal)
    clock = SimClockPublisher(session(zenoh), config.robot.name)
    scene = (ScenePublisher(session(zenoh), config.robot.name)
             if config.scene or config.floating_base else None)
    stalls = StallPublisher(session(zenoh), config.robot.name)
    simulator.on_stall = stalls.publish
    if not args.timing.lock_step:           # the controller's messages delivered late
        watch_deliveries((simulated.bus for simulated in simulator.buses), stalls.publish)
    side_work = [(_print_status, args.status_period), (_publish_clock, (clock, scene)),
                 (_inject, drive_faults)] + ([(_publish_ros_clock, ros_clock)] if ros_clock else [])
    threads = [threading.Thread(target=work, args=(simulator, argument, stop), daemon=True)
               for work, argument in side_work]
    try:
        simulator.start()
        # alive once its drives are on the bus and have sent their boot-ups: hil up releases
        # the controller then, and a master's first NMT reset never meets a drive still
        # powering on (a lock-step log held a boot-up of each that no replay answers)
        token = session(zenoh).liveliness().declare_token(f"hil/{config.robot.name}/sim")
        gc.collect()
        gc.freeze()     # start-up's objects out of the collector's way: shorter passes in the loop
        print(f"hil sim: {config.robot.name}, {len(config.drives)} drive(s) on "
              f"{', '.join(f'{b.name} ({buses[b.name].channel_info})' for b in config.buses)}, "
              f"{args.timing}, plant {config.plant_rate_hz:g} Hz, "
              f"cycle {config.cycle_hz:g} Hz; {scheduling}", flush=True)
        for sensor, served in zip(config.imus, simulator.sensors):
            print(f"hil sim: sensor '{sensor.name}': {sensor_line(sensor)} "
                  f"({served.port.device})", flush=True)
        for sensor in config.force_torques:
            print(f"hil sim: sensor '{sensor.name}': {sensor_line(sensor)}", flush=True)
        print(f"hil sim: your own master's node ids, frames, units and PDO maps: hil describe "
              f"{args.config}", flush=True)
        for thread in threads:
            thread.start()
        simulator.run(args.duration)
    finally:
        stop.set()
        for thread in threads[1:]:          # the clocks' last puts before their sessions close
            if thread.is_alive():
                thread.join()
        for face in (clock, scene, ros_clock, stalls):
            if face is not None:
                face.close()
        simulator.close()
        if token is not None:
            token.undeclare()
        for bus in buses.values():
            bus.shutdown()
        close_all()
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    for line in common.bus_report(buses) + frame_report(simulator):
        print(f"hil sim: {line}")
    if not args.timing.lock_step:
        print(f"hil sim: {simulator.stalls.summary()}")
    print("hil sim: stopped; all drives disabled", flush=True)
    return 0


def _faults(args: argparse.Namespace,
            config) -> tuple[list[FrameFault], list[DriveFault], list[SensorFault]]:
    """The --fault specs: (frame faults, drive faults, sensor faults), each drive and sensor
    one of the config's."""
    faults = [parse_fault(text) for text in args.fault]
    if any(isinstance(f, ProcessFault) for f in faults):
        raise HilError.single("kill faults are for `hil up --fault`",
                              hint="hil sim takes frame, drive and sensor faults")
    drive_faults = [f for f in faults if isinstance(f, DriveFault)]
    _check_drive_faults(config, drive_faults)
    sensor_faults = [f for f in faults if isinstance(f, SensorFault)]
    names = [sensor.name for sensor in config.sensors]
    for fault in sensor_faults:
        if fault.sensor not in names:
            raise HilError.single(f"--fault {fault.kind.value}:{fault.sensor}@{fault.at:g}: no "
                                  "sensor of that name", config.path,
                                  hint=f"sensors: {', '.join(names) or 'none in this config'}")
    return [f for f in faults if isinstance(f, FrameFault)], drive_faults, sensor_faults


def _open(args: argparse.Namespace, config, zenoh, frame_faults: list[FrameFault]):
    """(the simulator on its buses, the buses, the ROS 2 clock face or None)."""
    interface, channels = common.can_overrides(args)
    common.announce_await_monitor(args, "sim")
    buses = with_frame_faults(open_buses(config, zenoh, interface, channels,
                                         lossless=args.timing.lock_step,
                                         await_monitor=args.await_monitor), frame_faults,
                              args.fault_seed)
    try:
        simulator = Simulator(config, buses, args.timing)
        # after hil's own session: Zenoh's runtime threads, which every session of the
        # process shares, are made by the first one, and must be made under the real-time
        # settings above (made first by the ROS session, the frames' threads ran under the
        # normal scheduler on any CPU)
        return simulator, buses, _ros_clock(args, config)
    except BaseException:       # e.g. MuJoCo rejects the model: no bus may keep us alive
        for bus in buses.values():
            bus.shutdown()
        close_all()
        raise


def frame_report(simulator: Simulator) -> list[str]:
    """What the drives refused (malformed frames) and could not send, per bus."""
    lines = []
    for simulated in simulator.buses:
        refused = sum(drive.malformed for drive in simulated.drives)
        lost = simulated.router.lost_frames if simulated.router is not None else 0
        lines.append(f"bus {simulated.config.name}: the drives refused {refused} malformed "
                     f"frame(s) and could not send {lost}")
    return lines


def status_lines(simulator: Simulator) -> list[str]:
    """The plant's time and every drive's state, position and torque, a line each."""
    with simulator.lock:
        plant = simulator.plant
        lines = [f"t = {plant.time:8.3f} s   cycles {simulator.cycles}   "
                 f"{simulator.timing}"]
        joints = dict(zip(plant.joint_names, plant.joint_positions()))
        for simulated in simulator.buses:
            name = simulated.config.name
            if simulated.router is not None and simulated.router.lost_frames:
                lines.append(f"  {name:>8} lost {simulated.router.lost_frames}"
                             " frame(s) the bus would not send")
            for drive, config in zip(simulated.drives, simulated.config.drives):
                status = drive.core.status()
                positions = " ".join(f"{j}={joints[j]:+.4f}" for j in config.joints)
                fault = f"  FAULT {status.fault.text}" if status.fault else ""
                lines.append(f"  {name:>8} node {drive.node_id:>3} "
                             f"{drive.protocol.name:<7} {drive.state_text:<34} "
                             f"{positions}  torque {status.torque:+.4f} N·m{fault}")
        return lines


def _print_status(simulator: Simulator, period: float, stop: threading.Event) -> None:
    if period <= 0:
        return
    while not stop.wait(period):
        print("\n".join(status_lines(simulator)), flush=True)


def _publish_clock(simulator: Simulator, publishers: tuple[SimClockPublisher,
                                                          ScenePublisher | None],
                   stop: threading.Event) -> None:
    """The plant's time against the wall clock, for placing samples on the sim-time timeline;
    and its scene where it has one (moving objects, contacts and a floating base, for the
    recording)."""
    clock, scene = publishers
    plant = simulator.plant
    moving = plant.moving_objects()
    while not stop.wait(CLOCK_PERIOD):
        with simulator.lock:
            sim_time, wall_time = plant.time, time.time()
            if scene is not None:
                poses = [plant.object_pose(name) for name in moving]
                points, forces = plant.contacts()
                base = plant.base_pose() if plant.floating else None
        clock.publish(wall_time, sim_time)
        if scene is not None:
            scene.publish(SceneState(
                wall_time, sim_time, moving, np.array([p for p, _ in poses]).reshape(-1, 3),
                np.array([q for _, q in poses]).reshape(-1, 4), points, forces, base))


def _ros_clock(args: argparse.Namespace, config):
    """The simulator's ROS 2 face (/clock), or None without --ros."""
    settings = common.ros_settings(args)
    if settings is None:
        return None
    from hil.messaging.ros.face import RosClockFace     # noqa: PLC0415 (only with --ros)
    face = RosClockFace(settings, facts={
        "robot": config.robot.name, "plant_rate_hz": float(config.plant_rate_hz),
        "cycle_hz": float(config.cycle_hz), "lock_step": args.timing.lock_step})
    print(f"hil sim: ROS 2 node hil_sim on domain {settings.domain_id} via {settings.router}: "
          "/clock", flush=True)
    return face


def _publish_ros_clock(simulator: Simulator, face, stop: threading.Event) -> None:
    """/clock: the plant's time, in real time as in lock-step (use_sim_time nodes follow
    the plant either way). Side work: below the frames' priority, and without the
    simulator's lock (one float read), encoded by a struct.pack (cdr.time_cdr)."""
    enter_side_work()
    while not stop.wait(ROS_CLOCK_PERIOD):
        face.publish(simulator.plant.time)


def _check_drive_faults(config, faults: list[DriveFault]) -> None:
    """Each drive fault names a node id a drive may have on its bus when the fault fires
    (found then: :func:`_inject`): one the config gives, or, where a drive boots without one
    for an LSS master to give (CiA 305), one its protocol allows."""
    known = {(bus.name, drive.node_id) for bus in config.buses for drive in bus.drives
             if drive.node_id != protocol(drive.protocol).unconfigured_node_id}
    given = {(bus.name, node_id) for bus in config.buses for drive in bus.drives
             if drive.node_id == protocol(drive.protocol).unconfigured_node_id
             for node_id in protocol(drive.protocol).node_ids}
    for fault in faults:
        if (fault.bus, fault.node_id) in known | given:
            continue
        named = ", ".join(f"{bus}/{node_id}" for bus, node_id in sorted(known))
        lss = "".join(f"; on {bus}, the node id an LSS master gives a drive"
                      for bus in sorted({bus for bus, _ in given}))
        raise HilError.single(f"--fault {fault.kind.value}:{fault.bus}/{fault.node_id}: "
                              "no such drive", config.path, hint=f"drives: {named}{lss}")


def _inject(simulator: Simulator, faults: list[DriveFault], stop: threading.Event) -> None:
    """Each drive fault at its time: seconds of the plant's time after every drive was
    first enabled (the controller has the bench running). In lock-step the plant's time is
    the run's own, so a fault falls on the same moment of the run however fast it goes. The
    drive is the one with the node id then (an LSS master may have given it); where none or
    two have it, hil sim says so and goes on without that fault."""
    if not faults:
        return
    while not all(d.core.power is Power.ENABLED for d in simulator.drives):
        if stop.wait(0.01):
            return
    started = simulator.now()
    for fault in sorted(faults, key=lambda f: f.at):
        while simulator.now() < started + fault.at:
            if stop.wait(min(INJECT_POLL, started + fault.at - simulator.now())):
                return
        try:
            simulator.inject(fault.kind, simulator.drive(fault.bus, fault.node_id))
        except HilError as refused:
            print(f"hil sim: --fault {fault.kind.value}:{fault.bus}/{fault.node_id} not "
                  f"injected:\n{refused}", file=sys.stderr, flush=True)
            continue
        print(f"hil sim: injected {fault.kind.value} on {fault.bus}/{fault.node_id}", flush=True)
