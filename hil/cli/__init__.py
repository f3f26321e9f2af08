"""The ``hil`` command: one sub-command per module in this package.

User errors (:class:`~hil.errors.HilError`) are printed as diagnostics and
exit with status 1; no traceback is shown for them.
"""

from __future__ import annotations

import argparse
import sys

from hil.cli import bench, check, common, control, reset, send, sim, up, viz
from hil.errors import HilError

#: sub-command name -> module with ``add_arguments(parser)`` and ``run(args) -> int``
COMMANDS = {"check": check, "sim": sim, "control": control, "send": send, "reset": reset,
            "viz": viz, "up": up, "bench": bench}


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="hil", description="Hardware-in-the-loop controller stack for robot arms.")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, module in COMMANDS.items():
        sub = commands.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    common.end_with_parent_if_asked()
    parser = build_parser()
    args, extras = parser.parse_known_args(argv)
    # argparse cannot match positionals given after options (`hil send ur3 --connect EP
    # FILE`); commands with a variable `target` list take such leftovers
    if extras and hasattr(args, "target") and not any(e.startswith("-") for e in extras):
        args.target += extras
    elif extras:
        parser.error(f"unrecognized arguments: {' '.join(extras)}")
    try:
        return COMMANDS[args.command].run(args)
    except HilError as exc:
        print(exc, file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
