"""``hil ls``: the robots and hil processes reachable from here, and how this host meets."""

from __future__ import annotations

import argparse

from hil.cli import common
from hil.errors import ProcessError
from hil.zenoh_security import ROLES
from hil.zenoh_session import close_all, why_unreached

#: what each process' token stands for
PROCESSES = {"sim": "hil sim: drives and plant",
             "control": "hil control: CAN master and controllers",
             "viz": "hil viz: visualiser and recorder"}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--timeout", type=common.duration, default=2.0, metavar="TIME",
                        help="how long to wait for the processes' answers, e.g. 2s (default 2s)")
    common.add_zenoh(parser, "observer")


def run(args: argparse.Namespace) -> int:
    zenoh = common.zenoh_settings(args)
    try:
        found = common.tokens(zenoh, "hil/*/*", args.timeout)
    finally:
        close_all()
    where = ("meeting point " + zenoh.meet if zenoh.meet else
             f"listen {list(zenoh.listen)}, connect {list(zenoh.connect)}")
    if not found:
        why = why_unreached(zenoh)
        raise ProcessError.single(
            f"no hil process is reachable ({where}){f': {why}' if why else ''}",
            hint="start one (hil up ROBOT, or hil sim / hil control CONFIG), or give the "
                 "endpoints it listens on (--connect)")
    robots: dict[str, list[str]] = {}
    for token in found:
        _, robot, process = token.split("/", 2)
        robots.setdefault(robot, []).append(process)
    print(f"hil ls: {len(robots)} robot(s) reachable ({where})")
    for robot, processes in sorted(robots.items()):
        print(f"  {robot}")
        for process in processes:
            print(f"    {process:8s} {PROCESSES.get(process, process)} "
                  f"(role {_role(process)})")
    return 0


def _role(process: str) -> str:
    """The role ``hil <process>`` takes under --secure (hil.zenoh_security.ROLES)."""
    return next((role for role, commands in ROLES.items()
                 if f"hil {process}" in commands.split(", ")), "?")
