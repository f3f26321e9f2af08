"""The ``hil`` command: one sub-command per module in this package, imported only when it
runs (``hil control`` loads the master's modules and none of the simulator's).

hil's errors (:class:`~hil.errors.HilError`: a config's or a command line's, a running
bench's) are printed as diagnostics and exit with their status (1); no traceback is shown
for them.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from types import ModuleType

from hil import __version__
from hil.cli.output import READER_LEFT_STATUS, ReaderGone, guarded_output, to_devnull
from hil.errors import HilError
from hil.supervisor import end_with_parent_if_asked

#: sub-command name (and module hil.cli.<name>, with ``add_arguments(parser)`` and
#: ``run(args) -> int``) -> its one-line help
COMMANDS = {
    "check": "validate a robot (.xacro/.urdf) or a bus config (.yaml) and print a summary",
    "init": "write a bus config for a robot description (drives, transmissions, buses)",
    "describe": "print what a master needs to drive a config's drives: how to join each bus, "
                "node ids, frames, units, the EDS and its PDO mapping",
    "sim": "run the plant and all virtual drives of a bus config",
    "control": "run the CAN master, joint state publisher and joint trajectory controller",
    "send": "send a joint trajectory to a running hil control and wait for the result",
    "controllers": "list a running hil control's controllers, or switch between them "
                   "(trajectory, forward position, forward velocity)",
    "reset": "reset drive faults (after a fault aborted a goal) and hold position",
    "ls": "list the robots and hil processes reachable from here (sim, control, viz)",
    "viz": "show and record every axis of a running robot in rerun",
    "review": "open a recorded run (whole or in segments): its faults with their times, then "
              "the viewer",
    "replay": "feed a CAN log's master frames to a bus config's drives and compare every "
              "answer with the log's",
    "up": "start sim, controller and visualiser together (optionally run a demo), record the run",
    "keys": "make the certificates of --secure (mutual TLS and rights by role)",
    "router": "run a Zenoh router with rmw_zenohd's settings (for --ros without ROS 2 installed)",
    "bench": "measure cycle timing, real-time factors, overheads, latency, tracking and bus load",
}


def command_module(name: str) -> ModuleType:
    """The module of sub-command ``name``."""
    return importlib.import_module(f"hil.cli.{name}")


def build_parser(argv: list[str]) -> argparse.ArgumentParser:
    """The parser, with the options of the one sub-command named in ``argv`` (the others
    show their help line only, and their modules stay unimported)."""
    parser = argparse.ArgumentParser(
        prog="hil", description="Hardware-in-the-loop controller stack for robot arms.")
    parser.add_argument("--version", action="version", version=f"hil {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    chosen = next((word for word in argv if word in COMMANDS), None)
    for name, text in COMMANDS.items():
        sub = commands.add_parser(name, help=text, description=text)
        if name == chosen:
            command_module(name).add_arguments(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    end_with_parent_if_asked()
    argv = sys.argv[1:] if argv is None else argv
    parser = build_parser(argv)
    args, extras = parser.parse_known_args(argv)
    # argparse cannot match positionals given after options (`hil send ur3 --connect EP
    # FILE`); commands with a variable `target` list take such leftovers
    if extras and "target" in vars(args) and not any(e.startswith("-") for e in extras):
        args.target += extras
    elif extras:
        parser.error(f"unrecognized arguments: {' '.join(extras)}")
    with guarded_output():
        try:
            status = command_module(args.command).run(args)
        except HilError as exc:
            print(exc, file=sys.stderr)
            status = exc.exit_status
        except KeyboardInterrupt:
            status = 130
        except BrokenPipeError:    # written past the guard (to a stream's buffer directly)
            to_devnull(sys.stdout)
            ReaderGone.left, status = True, READER_LEFT_STATUS
    return READER_LEFT_STATUS if ReaderGone.left else status
