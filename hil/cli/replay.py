"""``hil replay LOG CONFIG``: a CAN log's master frames fed to CONFIG's simulated drives,
every answer compared with the log's; exit 1 at a divergence beyond the tolerances.

Exit status: 0 every answer matched (within the tolerances); 1 a divergence, or a log or
config that does not fit (the message says which)."""

from __future__ import annotations

import argparse
from pathlib import Path

from hil.bus_config import load_bus_config
from hil.cli import common
from hil.cli.written_files import previous_outputs
from hil.replay import (
    LOG_CLOCK_TOLERANCES, REAL_TIME_SHARE, REORDER_WINDOW, Replay, Report, Tolerances, frames,
    log_clock, not_whole, parse_channels, survey,
)
from hil.replay.compare import UNITS

CLOCKS = ("auto", "cycles", "log")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("log", type=Path,
                        help="the CAN log: .blf, .asc, .log (candump), .csv, .trc (.mf4 "
                             "with asammdf); or a folder of a log per bus, each named after "
                             "its bus (arm.blf: what hil_drives and DrivesBench.log_to keep)")
    parser.add_argument("config", help="the bus config to replay against (name or .yaml)")
    parser.add_argument("--channel", action="append", default=[], metavar="LOGCHANNEL=BUS",
                        help="the bus of a channel of the log (repeat; default: BLF and ASC "
                             "channels 1, 2, ... are the config's buses in order, named "
                             "channels match a bus' channel or name, a folder's files the bus "
                             "each is named after)")
    parser.add_argument("--clock", choices=CLOCKS, default="auto",
                        help="cycles: the plant one period per cycle, bit for bit (a lock-step "
                             "run's log); log: the plant on the log's timestamps (a real-time "
                             "run's or a robot's); auto: log where the master cycled in "
                             f"the config's period over {REAL_TIME_SHARE * 100:.0f} %% of the log's "
                             "time, else cycles")
    parser.add_argument("--tolerance", action="append", default=[],
                        metavar="[JOINT:]QUANTITY=VALUE",
                        help="allowed difference (repeat): " + ", ".join(
                            f"{q} in {u}" for q, u in UNITS.items())
                        + " (the drive's encoder counts and rated torque); default 0 on the "
                          "cycles clock, " + ", ".join(
                              f"{q} {v:g}" for q, v in LOG_CLOCK_TOLERANCES.items())
                        + " on the log's")
    parser.add_argument("--record", type=Path, metavar="FILE.rrd",
                        help="write the logged and replayed positions and torques of every "
                             "joint side by side to a rerun recording")
    common.add_package_path(parser)


def run(args: argparse.Namespace) -> int:
    if args.record is not None:                 # before the replay, not at its end
        replaced = previous_outputs({"--record": args.record}, recording=args.record)
        if replaced:
            print(f"hil replay: replacing {', '.join(replaced)} (keep it: move it, or give "
                  "--record another name)", flush=True)
    config = load_bus_config(common.config_path(args.config), common.package_path(args))
    found = survey(args.log, config, parse_channels(args.channel, config))
    clock = log_clock(found) if args.clock == "auto" else args.clock
    tolerances = Tolerances.parse(args.tolerance,
                                  LOG_CLOCK_TOLERANCES if clock == "log" else {}, config)
    buses = ", ".join(b.name for b in config.buses)
    kind = ("cycle by cycle, the plant one period a cycle" if clock == "cycles"
            else "on the log's own clock")
    print(f"hil replay: {args.log}: {found.frames} frames over {found.duration:.2f} s, "
          f"{found.cycles} cycles on {len(config.buses)} bus(es) ({buses}); replayed {kind} "
          f"(--clock {clock})", flush=True)
    cut = not_whole(args.log)
    if cut:
        print(f"hil replay: {args.log} is not whole: {cut}", flush=True)
    if found.disorder > REORDER_WINDOW:
        print(f"hil replay: its frames are written up to {found.disorder:.2f} s out of time "
              "order (a monitor that fell behind one sender more than another): read in time "
              "order", flush=True)
    report = Replay(config, found, clock, tolerances,
                    keep_values=args.record is not None).run(frames(
                        args.log, config, found.channels, found.reorder_window))
    for line in summary(report, tolerances):
        print(line)
    if args.record is not None:
        from hil.replay.record import record_replay
        record_replay(report, config.robot.name, config.cycle_hz, args.record)
        print(f"hil replay: logged and replayed values in {args.record}")
    return 1 if report.divergence_count else 0


def summary(report: Report, tolerances: Tolerances) -> list[str]:
    """What a replay found, for people: counts, the first divergence, per-joint numbers."""
    lines = [f"hil replay: {report.cycles} cycles ({report.plant_seconds:.2f} s of plant time) "
             f"replayed in {report.survey_seconds + report.wall_seconds:.2f} s, the log read "
             f"first included ({report.speed:.1f}x real time); {report.compared} answers compared, "
             f"{report.states_checked} heartbeat states found in order"
             + (f", {report.derived_unchecked} derived values (statusword bits the position loop "
                "sets, currents, powers) not held to "
                "a tolerance" if report.derived_unchecked else "")
             + (f", {report.sensor_frames} sensor frames compared" if report.sensor_frames
                else "")
             + (f", {report.sensor_frames_unchecked} sensor frames not compared (a real-time "
                "log's follow the plant's exact state, which a replay does not repeat)"
                if report.sensor_frames_unchecked else "")
             + (f", {report.after_the_log} answers after the log's end not compared"
                if report.after_the_log else "")]
    if report.seeded:
        lines.append(f"hil replay: the plant placed where the log's drives first reported "
                     f"{report.seeded} joint(s), once the master cycled; {report.before_seed} "
                     "measured values before it settled not compared")
    if not report.divergence_count:
        exact = "bit for bit" if tolerances.exact else "within the tolerances"
        lines.append(f"hil replay: 0 divergences: every answer as logged, {exact}")
    else:
        lines.append(f"hil replay: {report.divergence_count} divergence(s) ("
                     + ", ".join(f"{d}: {n}" for d, n in sorted(report.by_drive.items()))
                     + ")")
        lines.append(f"  the first: {report.first}")
        for other in report.first_cycle()[1:4]:
            lines.append(f"  in that cycle too: {other}")
    lines += statistics(report)
    return lines


def statistics(report: Report) -> list[str]:
    """Per joint: the replay's differences from the log (rms, max, where largest)."""
    stats = report.statistics
    if stats is None or not stats.count.any():
        return []
    rms, largest = stats.rms(), stats.largest
    lines = ["per joint, replay - log (joint units: rad or m, rad/s or m/s, N·m or N):",
             f"  {'joint':<20} {'position rms':>13} {'max':>10} {'velocity rms':>13} "
             f"{'max':>10} {'torque rms':>11} {'max':>10}  largest in second(s)"]
    for j, joint in enumerate(stats.joints):
        if not stats.count[:, j].any():
            continue
        worst = stats.worst_seconds(0, j)
        lines.append(f"  {joint:<20} {rms[0, j]:>13.3g} {largest[0, j]:>10.3g} "
                     f"{rms[1, j]:>13.3g} {largest[1, j]:>10.3g} {rms[2, j]:>11.3g} "
                     f"{largest[2, j]:>10.3g}  "
                     + ", ".join(f"{s} s ({v:.2g})" for s, v in worst if v > 0))
    return lines
