"""The processes of ``hil up``: each robot's sim and controller and the one visualiser, as
``hil`` commands, and their start in order."""

from __future__ import annotations

import argparse
from functools import partial
from pathlib import Path

from hil.bus_config import SystemConfig
from hil.can.faults import ProcessFault
from hil.cli import common
from hil.cli.up.robots import RobotRun
from hil.errors import UsageError
from hil.hardware import BOOT_TIMEOUT
from hil.messaging.zenoh_api import ProcessWatch, RunSubscriber
from hil.realtime import lock_step_cpus, real_time_cpus
from hil.supervisor import RECORDER_STOP_TIMEOUT, Child, Run, cpus_argument, wait_alive
from hil.zenoh_session import ZenohSettings, session

#: the visualiser's status lines (cycles, losses, the recording's lag) in viz.log, every (s)
VIZ_STATUS_PERIOD = 60


def make_children(args: argparse.Namespace, robots: list[RobotRun], faults: list, logs: Path,
                  can_log: Path) -> Child:
    """Each robot's sim and control (into its ``children``) and the one visualiser (returned)
    as ``hil`` commands, placed on the CPUs in real time. Given no endpoints, they meet at
    the host's meeting point as single commands do (hil.zenoh_session), so that `hil send`,
    `hil viz` or `hil reset` started beside ``hil up`` with their defaults find them."""
    several = len(robots) > 1
    sim_faults = [f"--fault={text}" for text, f in zip(args.fault, faults)
                  if not isinstance(f, ProcessFault)]
    shared = [*(["--secure", str(args.secure)] if args.secure else []),
              *(f"--package-path={p}" for p in args.package_path)]
    lock_step = ["--lock-step"] if args.timing.lock_step else []
    # the visualiser logs the CAN buses: in lock-step, whole from each process' first frame
    logged = ["--await-monitor"] if args.timing.lock_step else []
    # over TLS the processes are not pinned to a CPU each: pinned, every `hil up ur3 --secure`
    # on 2 CPUs faulted within a second as soon as a third process took the traffic,
    # unpinned every run was clean (docs/performance.md, "Stalls of the bench, told apart
    # from drive faults (2026-11-24, issue 28)")
    placement = lock_step_cpus() if lock_step else real_time_cpus()
    placed = {name: [] if args.secure else cpus_argument(cpus)
              for name, cpus in zip(("sim", "control", "viz"), placement)}
    for robot in robots:
        config = [str(robot.config_path), *can_options(args, robot.config), *shared]
        ros = _ros_options(args, robot.name, several)
        tag = robot.name if several else ""         # in its messages and its logs' names
        prefix = f"{tag}." if tag else ""
        robot.children = {
            "sim": Child("sim", ["sim", *config, *lock_step, *logged, *placed["sim"],
                                 "--status-period", "0", *sim_faults, *ros],
                         logs / f"{prefix}sim.log", tag),
            "control": Child("control", [
                "control", *config, *lock_step, *logged, *placed["control"], *ros,
                # the sim already runs: a drive silent at boot is a fault
                "--boot-timeout", f"{BOOT_TIMEOUT:g}", "--hold",
                *(["--ros-use-sim-time"] if args.ros_use_sim_time else [])],
                logs / f"{prefix}control.log", tag, held=True),
        }
    return Child("viz", ["viz", *(str(r.config_path) for r in robots),
                         *can_options(args, robots[0].config), *shared, *lock_step,
                         *placed["viz"], "--save", str(args.save),
                         *(["--segment", args.segment] if args.segment else []),
                         # a line a minute in viz.log: the recording's lag over a long run
                         "--status-period", str(VIZ_STATUS_PERIOD),
                         "--can-log", str(can_log), *viewer_options(args)],
                 logs / "viz.log", stop_timeout=RECORDER_STOP_TIMEOUT)


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


def start_in_order(robots: list[RobotRun], viz: Child, supervised: Run, zenoh: ZenohSettings,
                   watchers: list, together: bool = False) -> None:
    """Start the sims, the visualiser and the controllers in turn, each once the one before
    is alive on Zenoh; the controllers held before their bring-up until all of them have
    started, so that no real-time loop runs while another process starts (the import of a
    controller took the CPU from the first robot's loop until its drives fell silent, in every
    run of ``hil up ur3 pigot`` on 2 CPUs: docs/performance.md, "Two robots on 2 CPUs: `hil up
    ur3 pigot --duration 60` (2026-11-28, issue 48)"). ``together`` (lock-step,
    where no loop can be starved): all of them started at once, their imports overlapping,
    then waited for in the same order (Zenoh's meeting point takes any order of start). The
    watchers it makes go into ``watchers`` (to be closed however the start ends)."""
    watches: dict[str, ProcessWatch] = {}

    def start(child: Child) -> None:
        child.start()
        supervised.children.append(child)
        if not watches:        # the first sim holds the meeting point, or has joined it
            for each in robots:
                watches[each.name] = ProcessWatch(session(zenoh), each.name)
                progress = each.progress
                watchers.extend([watches[each.name], RunSubscriber(
                    session(zenoh), each.name, progress.on_samples, lambda wall, sim: None,
                    progress.problems.append, progress.on_diagnostic, progress.on_stall,
                    progress.on_scene)])

    def sim_alive(robot: RobotRun) -> None:
        wait_alive(supervised, watches[robot.name].wait_alive, robot.children["sim"])

    def viz_alive() -> None:       # the one visualiser declares itself for every robot
        wait_alive(supervised, lambda name, timeout: all(
            watches[robot.name].wait_alive(name, timeout) for robot in robots), viz)

    def control_held(robot: RobotRun) -> None:
        supervised.wait_until(robot.children["control"], lambda timeout: watches[
            robot.name].wait_alive("control/held", timeout),
            "started (waiting to bring its drives up)")

    # the visualiser starts before the controllers: its start-up (rerun, the robot models)
    # is CPU-heavy, and must not starve the first real-time cycles
    steps = [*((robot.children["sim"], partial(sim_alive, robot)) for robot in robots),
             (viz, viz_alive),
             *((robot.children["control"], partial(control_held, robot)) for robot in robots)]
    if together:
        for child, _ in steps:
            start(child)
    for child, alive in steps:
        if not together:
            start(child)
        alive()
        if supervised.stop.is_set():
            return
    for robot in robots:
        robot.children["control"].release()
    for robot in robots:
        wait_alive(supervised, watches[robot.name].wait_alive, robot.children["control"])
        if supervised.stop.is_set():
            return


def can_options(args: argparse.Namespace, config: SystemConfig) -> list[str]:
    options = [f"--channel={c}" for c in args.channel]
    if args.interface:
        options.append(f"--interface={args.interface}")
    if args.can:
        if len(args.can) != len(config.buses):
            raise UsageError.single(
                f"--can gave {len(args.can)} channel(s) for {len(config.buses)} bus(es) "
                f"({', '.join(b.name for b in config.buses)})", config.path,
                hint="give one --can CHANNEL per bus, in the config's order")
        options = ["--interface=socketcan"] + [f"--channel={bus.name}={channel}" for bus, channel
                                               in zip(config.buses, args.can)]
    return options


def viewer_options(args: argparse.Namespace) -> list[str]:
    options = []
    if args.spawn or (not args.no_viewer and common.display_available()):
        options.append("--spawn")
    if args.viewer:
        options += ["--viewer", args.viewer]
    return options
