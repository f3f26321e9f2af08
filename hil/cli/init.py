"""``hil init DESCRIPTION``: write a bus config a user can run at once (see
:mod:`hil.commissioning.initial`), then load it back as every other command will."""

from __future__ import annotations

import argparse
from pathlib import Path

from hil.bus_config import load_bus_config
from hil.bus_config.locate import shipped_names
from hil.commissioning.coupled_loops import coupled_gains
from hil.commissioning.initial import initial_config
from hil.commissioning.watchdog import watchdog_choices
from hil.cli import common
from hil.description import load_description
from hil.errors import ConfigError, UsageError
from hil.protocols import BUILTIN, protocol
from hil.protocols.base import CanFd
from hil.resources import BUS_CONFIGS, data_dir


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("description", type=Path,
                        help="robot description (.xacro or .urdf), or the name of a robot "
                             f"hil ships ({shipped_names()}): its description")
    parser.add_argument("--protocol", choices=sorted(BUILTIN), default="cia402",
                        help="the drives' protocol (default cia402)")
    parser.add_argument("--motor", metavar="MODEL",
                        help="the product every drive is, for a protocol that knows its "
                             "makers' models (damiao: DM4310, DM4340, DM8009, ...; "
                             "cubemars: AK60-6_V3.0, AK80-6, ...; robstride: RS00, RS02-RS04, "
                             "CyberGear; myactuator: X4-24, X8-25, ...; moteus: mj5208, "
                             "be8108, ...): its ranges, torques and speed size the drives "
                             "(default: the smallest model that fits each joint)")
    parser.add_argument("--rate", type=common.positive, default=500.0, metavar="HZ",
                        help="control cycle rate of every bus (default 500)")
    parser.add_argument("--fd", action="store_true",
                        help="CAN FD buses, 1 Mbit/s arbitration and 5 Mbit/s data (as OpenArm's "
                             "and moteus' benches run), the drives per bus by their FD load: "
                             "for drives that speak FD (damiao; moteus speaks nothing else and "
                             "always gets them)")
    parser.add_argument("-o", "--output", type=Path, metavar="FILE.yaml",
                        help="where to write it (default: ROBOT.yaml in this folder)")
    parser.add_argument("--force", action="store_true", help="replace an existing file")
    common.add_package_path(parser)


def run(args: argparse.Namespace) -> int:
    if not args.rate > 0 or args.rate > 10_000:
        raise UsageError.single(f"--rate {args.rate:g}: give a control rate in Hz, e.g. 500")
    motor = _motor(args.protocol, args.motor)
    if args.fd and protocol(args.protocol).can_fd is CanFd.CLASSIC:
        raise UsageError.single(f"--fd: {args.protocol} drives speak classical CAN only",
                                hint="drop --fd, or pick a protocol whose drives speak CAN FD: "
                                     + ", ".join(sorted(name for name in BUILTIN
                                                        if protocol(name).can_fd
                                                        is not CanFd.CLASSIC)))
    package_path = common.package_path(args)
    if not args.description.exists() and args.description.suffix not in (".urdf", ".xacro"):
        args.description = _shipped_description(str(args.description), package_path)
    robot = load_description(args.description, package_path)
    output = args.output or Path(f"{robot.name}.yaml")
    if output.suffix not in (".yaml", ".yml"):
        raise UsageError.single(f"-o {output}: a bus config is a .yaml file")
    if output.exists() and not args.force:
        raise UsageError.single(f"{output} exists already", hint="give another -o, or --force")
    written = initial_config(robot, args.description, output, args.protocol, args.rate, motor,
                             fd=args.fd)
    if written.drives == 0:
        raise ConfigError.single(f"'{robot.name}' has no joint hil can drive: no movable joint "
                                 "that is not a mimic", args.description,
                                 hint="hil drives revolute, continuous and prismatic joints; "
                                      "check that this is the robot's main file, not an include")
    output.write_text(written.text)
    config = load_bus_config(output, package_path)      # as `hil check` and `hil up` will
    coupled = coupled_gains(config)
    if coupled.gains:                    # the drives' loops as hil sim would tune them fail
        written = initial_config(robot, args.description, output, args.protocol, args.rate,
                                 motor, coupled.gains, args.fd)
        output.write_text(written.text)
        config = load_bus_config(output, package_path)
    print(f"hil init: wrote {output}: {written.drives} {args.protocol} drive(s)"
          f"{f' ({motor})' if motor else ''} on "
          f"{written.buses} {'CAN FD ' if config.buses[0].fd else ''}bus(es) at {args.rate:g} Hz "
          f"for '{robot.name}'"
          f"{f'; {len(config.warnings)} warning(s), see hil check' if config.warnings else ''}")
    if written.standing is not None:
        print(f"  it stands ({written.standing.kind}, on {', '.join(written.standing.feet)}): a "
              f"floating base on a floor, starting with each foot under its hip; the demo "
              f"holds the {len(written.standing.carrying)} joint(s) it stands on")
    if coupled.gains:
        print(f"  {len(coupled.gains)} drive(s) get gains: tuned on the least inertia their "
              f"motor sees, their loops would move up to {coupled.ratio:.3g} times it "
              "together, past what they hold stably (hil/commissioning/coupled_loops.py)")
    for note in written.notes:
        print(f"  warning: {note}")
    for line in watchdog_choices(config):
        print(f"  {line}")
    for joint in written.defaulted:
        print(f"  warning: joint '{joint.joint}': {joint.note}; review 'joint_limits:' in "
              f"{output}")
    where = "".join(f" --package-path {folder}" for folder in args.package_path)
    print(f"next: hil check {output}{where} && hil up {output} --demo{where}")
    return 0


def _shipped_description(name: str, package_path) -> Path:
    """A robot's name: the description its bus config names."""
    try:
        config = common.config_path(name)
    except UsageError:
        shipped = sorted(p.stem for p in data_dir(BUS_CONFIGS).glob("*.yaml"))
        raise UsageError.single(f"robot description '{name}' does not exist",
                                hint="give the path of a .urdf or .xacro file, or a robot hil "
                                     f"ships: {', '.join(shipped)}") from None
    return load_bus_config(config, package_path).robot.source


def _motor(protocol_name: str, name: str | None) -> str | None:
    """``--motor``'s model, as the protocol names it; UsageError listing the known ones."""
    models = protocol(protocol_name).models
    if name is None:
        return None
    if not models:
        raise UsageError.single(f"--motor {name}: protocol '{protocol_name}' knows no makers' "
                                "models", hint="give the drives' limits in the bus config")
    found = next((key for key in models if _plain(key) == _plain(name)
                  or _plain(key) == "DM" + _plain(name)), None)
    if found is None:
        raise UsageError.single(f"--motor {name}: no {protocol_name} model of that name",
                                hint=f"one of: {', '.join(models)}")
    return found


def _plain(name: str) -> str:
    return name.upper().replace("-J", "").replace("-", "_")
