"""``hil bench``: timing and tracking figures of the whole stack, as a table and JSON."""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

from hil.bench import (
    DID_NOT_START, LOCK_STEP_WINDOW, BenchSettings, run_bench, run_scale, run_soak,
    runs_not_started, scale_not_started,
)
from hil.bench.scale import HOLDS_MISSED, largest_holding
from hil.cli import common
from hil.errors import UsageError
from hil.realtime.stalls import BENCH_STALL_STATUS
from hil.stack import START_ATTEMPTS, StackDidNotStart
from hil.supervisor import ChildFailed

#: what a row whose stack did not start shows in the table
NOT_STARTED = "did not start (why: the report's did_not_start)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.epilog = (
        "exit status: 0 every figure measured; 1 a run failed (the error names it); "
        f"{BENCH_STALL_STATUS} the report is whole but some real-time run did not start (an "
        f"in-process stack in {START_ATTEMPTS} attempts, or a process of a run across processes "
        "exited; the table names each, the report says why): a host that stalls past the "
        "drives' silence limits, or a regression; rerun to tell")
    parser.add_argument("--quick", action="store_true",
                        help="short runs (about a minute; what CI runs)")
    parser.add_argument("--seconds", type=common.duration, metavar="TIME",
                        help="length of each real-time run, e.g. 10s (default 10s; --quick 2s)")
    parser.add_argument("--json", type=Path, default=Path("bench.json"), metavar="FILE",
                        help="write the report here (default bench.json)")
    parser.add_argument("--soak", type=common.duration, metavar="TIME",
                        help="instead: repeat a trajectory for TIME (e.g. 10min, 90s) and "
                             "report drift, memory growth and missed cycles")
    parser.add_argument("--scale", type=_drive_counts, metavar="N,N,...",
                        help="instead: the scale sweep alone, robots of these many drives "
                             "(e.g. 6,12,24,34,64; ur3 arms on one base on hil init's buses: "
                             "CiA 402 on classical CAN below 1 kHz, Damiao on CAN FD from "
                             "1 kHz), each --seconds long in real time across processes, at "
                             "every --rate")
    parser.add_argument("--rate", type=common.positive, action="append", metavar="HZ",
                        help="with --scale: a cycle rate (repeat for several; default 500 "
                             "and 1000)")


def run(args: argparse.Namespace) -> int:
    settings = BenchSettings.quick() if args.quick else BenchSettings()
    if args.seconds is not None:
        settings = replace(settings, seconds=args.seconds)
    say = lambda text: print(text, file=sys.stderr, flush=True)  # noqa: E731
    if args.rate and not args.scale:
        raise UsageError.single("--rate is for --scale", hint="hil bench --scale 6,12 --rate 500")
    if args.soak and args.scale:
        raise UsageError.single("--soak and --scale are two benches", hint="give one of them")
    if args.scale:
        settings = replace(settings, scale_drives=args.scale,
                           scale_rates=tuple(args.rate or settings.scale_rates))
    try:
        if args.soak:
            return _soak(args, settings, say)
        return _scale(args, settings, say) if args.scale else _bench(args, settings, say)
    except (StackDidNotStart, ChildFailed) as failure:
        # a lock-step run, which no stall of the host fails, or the soak's one long run
        say(f"hil bench: error: {failure}")
        return 1


def _soak(args: argparse.Namespace, settings: BenchSettings, say: Callable[[str], None]) -> int:
    soak = run_soak(args.soak, settings, say=say)
    args.json.write_text(json.dumps({"soak": soak}, indent=2))
    print(f"soak {soak['seconds']:g} s, {soak['robot']}: {soak['repetitions']} repetitions, "
          f"{soak['failed']} failed; final position error first {soak['final_error_first']:.5f}"
          f", last {soak['final_error_last']:.5f}, max {soak['final_error_max']:.5f}; "
          f"memory growth {soak['rss_growth_bytes'] / 1e6:.1f} MB, after the first repetition"
          f" {soak['rss_growth_after_first_bytes'] / 1e6:.2f} MB; missed {soak['missed']} "
          f"of {soak['cycles']} cycles")
    print(f"hil bench: report in {args.json}")
    return 0


def _drive_counts(text: str) -> tuple[int, ...]:
    """``6,12,24``: robot sizes for --scale (each at least one drive)."""
    try:
        counts = tuple(int(part) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a list of drive counts, e.g. "
                                         "6,12,24") from None
    if not counts or min(counts) < 1:
        raise argparse.ArgumentTypeError(f"'{text}': each drive count must be 1 or more")
    return counts


def _scale(args: argparse.Namespace, settings: BenchSettings, say: Callable[[str], None]) -> int:
    report = run_scale(settings, say=say)
    args.json.write_text(json.dumps(report, indent=2))
    print("\n".join(_scale_lines(report)).lstrip("\n"))
    print(f"\nhil bench: report in {args.json}")
    return _status(scale_not_started(report["scale"]), say)


def _bench(args: argparse.Namespace, settings: BenchSettings, say: Callable[[str], None]) -> int:
    report = run_bench(settings, say=say)
    args.json.write_text(json.dumps(report, indent=2))
    print(format_table(report))
    print(f"\nhil bench: report in {args.json}")
    return _status(runs_not_started(report), say)


def _status(not_started: list[str], say: Callable[[str], None]) -> int:
    """The exit status of a whole report: BENCH_STALL_STATUS, saying which, where some
    real-time run did not start."""
    if not_started:
        say(f"hil bench: {len(not_started)} real-time run(s) did not start: "
            f"{', '.join(not_started)}; their figures are missing from the report")
        # the report is whole, but a host that stalls past the drives' silence limits (or a
        # regression of the real-time bring-up: the lock-step runs, which no stall fails, ran)
        return BENCH_STALL_STATUS
    return 0


def _cycle_columns(name: str, row: dict) -> str:
    """A control-cycle row's period and busy columns, under format_table's header."""
    return (f"{name:<6} {row['rate_hz']:>5.0f} {row['cycles']:>7} {row['period_mean_ms']:>8.3f} "
            f"{row['error_p50_us']:>7.0f} {row['error_p99_us']:>7.0f} "
            f"{row['error_max_us']:>7.0f} {row['missed']:>6} {row['busy_p50_us']:>9.0f} "
            f"{row['busy_p99_us']:>7.0f}")


def _cycle_lines(report: dict) -> list[str]:
    """The machine and the real-time control cycle in one process."""
    floor = report["timing_floor"][0]
    machine = report["machine"]
    lines = [f"machine: {machine['cpus']} CPUs, Python {machine['python']}, drive core "
             f"{machine['drive_core']}",
             "", "control cycle, real time (in-process virtual CAN, Zenoh on loopback), "
             f"{report['control_cycle'][0]['scheduling']}",
             "  period error = |release to release - nominal|; busy = release to end of work",
             f"  {'robot':<6} {'Hz':>5} {'cycles':>7} {'mean ms':>8} {'p50 us':>7} {'p99 us':>7} "
             f"{'max us':>7} {'missed':>6} {'busy p50':>9} {'p99 us':>7} {'sim RTF':>8} "
             f"{'e2e p50 ms':>11} {'e2e p99 ms':>11}"]
    for cycle, latency in zip(report["control_cycle"], report["latency"]):
        if DID_NOT_START in cycle:
            lines.append(f"  {cycle['robot']:<6} {cycle['rate_hz']:>5.0f} {NOT_STARTED}")
            continue
        lines.append(
            f"  {_cycle_columns(cycle['robot'], cycle)} {cycle['sim_real_time_factor']:>8.2f} "
            f"{latency.get('p50_ms', float('nan')):>11.2f} "
            f"{latency.get('p99_ms', float('nan')):>11.2f}")
    lines.append(f"  {_cycle_columns('empty', floor)}   (the timing floor: the same pacing "
                 "with no work)")
    return lines


def _socketcan_lines(report: dict) -> list[str]:
    """Real time over SocketCAN, where vcan exists."""
    socketcan = report["socketcan"]
    if isinstance(socketcan, dict):
        return ["", f"SocketCAN: {socketcan['unavailable']}"]
    return ["", "SocketCAN: " + "; ".join(
        f"{r['robot']} {r['rate_hz']:g} Hz " + (NOT_STARTED if DID_NOT_START in r else
                                                 f"p99 {r['error_p99_us']:.0f} us, missed "
                                                 f"{r['missed']}") for r in socketcan)]


def _lock_step_lines(report: dict) -> list[str]:
    """Lock-step speed and the stack's overhead against bare python-can and MuJoCo."""
    lines = ["", "lock-step and overhead (per control cycle; quiet: the run's fastest quarter "
              f"of {LOCK_STEP_WINDOW * 1e3:.0f} ms windows)",
              f"  {'robot':<6} {'speed-up':>9} {'quiet':>6} {'stack us':>9} {'quiet':>6} "
              f"{'python-can us':>14} {'x':>5} {'MuJoCo us':>10} {'x':>6}"]
    for lock, over in zip(report["lock_step"], report["overhead"]):
        lines.append(f"  {lock['robot']:<6} {lock['speedup_over_real_time']:>9.2f} "
                     f"{lock['speedup_quiet_quartile']:>6.2f} {over['full_stack_cycle_us']:>9.0f} "
                     f"{lock['cycle_us_quiet_quartile']:>6.0f} "
                     f"{over['bare_python_can_cycle_us']:>14.0f} "
                     f"{over['ratio_to_python_can']:>5.1f} {over['bare_mujoco_cycle_us']:>10.1f} "
                     f"{over['ratio_to_mujoco']:>6.0f}")
    return lines


def _tracking_and_fault_lines(report: dict) -> list[str]:
    """Tracking against the ideal servo, and fault detection."""
    lines = ["", "tracking a fixed trajectory (rad/m): full stack (positions only; with the "
                 "velocity feed-forward; with velocity and gravity torque) vs MuJoCo's ideal "
                 "position servo"]
    for row in report["tracking"]:
        fed, weighed = row["feed_forward"], row["gravity_feed_forward"]
        lines.append(f"  {row['robot']:<6} {row['result']:<10} rms {row['rms']:.4f} max "
                     f"{row['max']:.4f}   velocity {fed['result']:<10} rms {fed['rms']:.4f} "
                     f"max {fed['max']:.4f}   + gravity {weighed['result']:<10} rms "
                     f"{weighed['rms']:.4f} max {weighed['max']:.4f}   ideal rms "
                     f"{row['ideal_servo_rms']:.4f} max {row['ideal_servo_max']:.4f}")
    lines += ["", "fault detection (ur3, 500 Hz: injected on bus 'arm')"]
    for row in report["fault_detection"]:
        when = (NOT_STARTED if DID_NOT_START in row else f"{row['detection_ms']:6.1f} ms"
                if row["detected"] else "NOT DETECTED")
        lines.append(f"  {row['fault']:<22} {when}  {row['first_report'] or ''}")
    return lines


def _across_process_lines(report: dict) -> list[str]:
    """The stack across processes beside the transport's floor."""
    lines = ["", "across processes (hil sim, hil control and with viz hil viz recording, over "
              "Zenoh on loopback);", "  floor: the same frames between two bare python-can "
              "processes on the same transport, this run; stalls over 5 ms of the sim's and "
              "the controller's loops and of Zenoh's deliveries (s/c/t); CPU: each "
              "process' share of a CPU (the floor's process in its place)",
              f"  {'robot':<8} {'Hz':>5} {'viz':>4} {'cycles':>7} {'p50 us':>7} {'p99 us':>7} "
              f"{'max us':>7} {'missed':>7} {'busy p50':>9} {'p99':>5} {'rt p50':>7} "
              f"{'p99':>5} {'floor p50':>10} {'p99':>5} {'x p99':>6} {'faults':>6} "
              f"{'stalls s/c/t':>12}  CPU"]
    for row in report["across_processes"]:
        if DID_NOT_START in row:
            lines.append(f"  {row['robot']:<8} {row['rate_hz']:>5.0f} "
                         f"{'yes' if row['viz'] else 'no':>4} {NOT_STARTED}")
            continue
        floor = row["floor"]
        cpu = _cpu_beside_floor(row)
        missed = f"{row['missed']} {100 * row['missed'] / max(row['cycles'], 1):.2f}%"
        stalls = "/".join(str(row.get("stalls", {}).get(process, {}).get("count", 0))
                          for process in ("sim", "control", "transport"))
        lines.append(
            f"  {row['robot']:<8} {row['rate_hz']:>5.0f} {'yes' if row['viz'] else 'no':>4} "
            f"{row['cycles']:>7} {row.get('error_p50_us', math.nan):>7.0f} "
            f"{row.get('error_p99_us', math.nan):>7.0f} {row.get('error_max_us', math.nan):>7.0f}"
            f" {missed:>7} {row.get('busy_p50_us', math.nan):>9.0f} "
            f"{row.get('busy_p99_us', math.nan):>5.0f} "
            f"{row.get('round_trip_p50_us', math.nan):>7.0f}"
            f" {row.get('round_trip_p99_us', math.nan):>5.0f} "
            f"{floor.get('round_trip_p50_us', math.nan):>10.0f} "
            f"{floor.get('round_trip_p99_us', math.nan):>5.0f} "
            f"{row['round_trip_p99_over_floor']:>6.2f} {row['faults']:>6} {stalls:>12}  {cpu}")
    return lines


def _cpu_beside_floor(row: dict) -> str:
    """Each process' CPU share, and in brackets what the floor's process that stands for it
    took (the transport alone)."""
    floor = row["floor"].get("cpu", {})
    return " ".join(f"{name} {share:.0%}" + (f" ({floor[name]:.0%})" if name in floor else "")
                    for name, share in row["cpu"].items())


def _lock_step_across_process_lines(report: dict) -> list[str]:
    """Lock-step across processes beside the same frames exchanged as fast as they come."""
    lines = ["", "lock-step across processes (hil sim and hil control --lock-step, over Zenoh on "
                 "loopback);", "  floor: the same frames between two bare python-can processes, "
                 "each cycle as soon as the last one's answers are in, this run; CPU: each "
                 "process' share of a CPU (the floor's process in its place)",
             f"  {'robot':<8} {'Hz':>5} {'cycles':>7} {'speed-up':>9} {'rt p50 us':>10} "
             f"{'p99':>6} {'floor speed-up':>15} {'rt p50 us':>10} {'p99':>6} {'of floor':>9}"
             "  CPU"]
    for row in report["lock_step_across_processes"]:
        floor = row["floor"]
        cpu = _cpu_beside_floor(row)
        lines.append(
            f"  {row['robot']:<8} {row['rate_hz']:>5.0f} {row['cycles']:>7} "
            f"{row['speedup_over_real_time']:>9.2f} {row.get('round_trip_p50_us', math.nan):>10.0f}"
            f" {row.get('round_trip_p99_us', math.nan):>6.0f} "
            f"{floor['speedup_over_real_time']:>15.2f} "
            f"{floor.get('round_trip_p50_us', math.nan):>10.0f} "
            f"{floor.get('round_trip_p99_us', math.nan):>6.0f} "
            f"{row['speedup_over_floor']:>8.0%}  {cpu}")
    return lines


def _scale_lines(report: dict) -> list[str]:
    """CPU per cycle against the robot's size, and the largest that held each rate."""
    lines = ["", "scale (ur3 arms on one base on hil init's buses: CiA 402 on classical CAN below "
                 "1 kHz, Damiao on CAN FD from 1 kHz; hil sim and hil control in real time "
                 "across processes, no visualiser);", "  CPU us a cycle: each process' "
                 "share of a CPU over the rate; holds: no fault and at most "
                 f"{HOLDS_MISSED:.1%} of the cycles missed; bare: hil sim with a bare "
                 "python-can master in hil control's place (its CPU us a cycle, its missed "
                 "cycles, the drives it enabled)",
             f"  {'drives':>6} {'Hz':>5} {'buses':>5} {'cycles':>7} {'missed':>7} "
             f"{'busy p50':>9} {'p99':>6} {'rt p99':>7} {'sim us':>7} {'ctl us':>7} "
             f"{'faults':>6}  holds  {'bare: sim us':>12} {'ctl us':>7} {'missed':>7} "
             "enabled"]
    for row in report["scale"]:
        if DID_NOT_START in row:
            lines.append(f"  {row['drives']:>6} {row['rate_hz']:>5.0f} {row['buses']:>5} "
                         f"{NOT_STARTED}")
            continue
        per_cycle = row["cpu_us_per_cycle"]
        lines.append(
            f"  {row['drives']:>6} {row['rate_hz']:>5.0f} {row['buses']:>5} {row['cycles']:>7} "
            f"{row['missed']:>7} {row['busy_p50_us']:>9.0f} {row['busy_p99_us']:>6.0f} "
            f"{row['round_trip_p99_us']:>7.0f} {per_cycle.get('sim', math.nan):>7.0f} "
            f"{per_cycle.get('control', math.nan):>7.0f} {row['faults']:>6}  "
            f"{'yes' if row['holds'] else 'no ':<5}  {_bare_columns(row.get('bare_master'))}")
    largest = largest_holding(report["scale"])
    lines.append("  largest that held: " + ", ".join(
        f"{rate:g} Hz {drives if drives is not None else 'none'}"
        + (" drives" if drives is not None else "") for rate, drives in largest.items()))
    return lines


def _bare_columns(bare: dict | None) -> str:
    """A scale row's bare-master figures, as the table's last columns (none in a report
    written before the sweep ran one)."""
    if bare is None:
        return f"{'-':>12}"
    if DID_NOT_START in bare:
        return f"{'':>12} {NOT_STARTED}"
    per_cycle = bare["cpu_us_per_cycle"]
    return (f"{per_cycle.get('sim', math.nan):>12.0f} {per_cycle.get('control', math.nan):>7.0f} "
            f"{bare['missed']:>7} {bare['enabled']}/{bare['drives']}")


def _bus_load_lines(report: dict) -> list[str]:
    """Each bus' measured and estimated load."""
    lines = ["", "bus load (measured nominal / worst-case stuffing; config estimate worst case)"]
    for row in report["bus_load"]:
        lines.append(f"  {row['robot']:<6} {row['rate_hz']:>5.0f} Hz {row['bus']:<6} "
                     f"{row['measured_frames_per_s']:>7.0f} frames/s  "
                     f"{100 * row['measured_load']:>5.1f} % / "
                     f"{100 * row['measured_load_worst_stuffing']:>5.1f} %  "
                     f"(estimate {100 * row['estimated_load_worst']:.1f} %)")
    return lines


def format_table(report: dict) -> str:
    """The report of ``hil bench`` as text tables, a section each."""
    sections = (_cycle_lines, _socketcan_lines, _lock_step_lines, _tracking_and_fault_lines,
                _across_process_lines, _lock_step_across_process_lines, _scale_lines,
                _bus_load_lines)
    return "\n".join(line for section in sections for line in section(report))
