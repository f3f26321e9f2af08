"""``hil reset ROBOT``: reset drive faults of a running hil control, and accept goals again."""

from __future__ import annotations

import argparse
import sys

from hil.cli import common
from hil.errors import HilError
from hil.messaging.zenoh_api import ControllerGone, TrajectoryActionClient
from hil.zenoh_session import close_all, session


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("robot", help="robot name, e.g. ur3")
    parser.add_argument("--timeout", type=float, default=15.0, help="seconds to wait (15)")
    common.add_zenoh(parser, listens=False)


def run(args: argparse.Namespace) -> int:
    client = TrajectoryActionClient(session(common.zenoh_settings(args)), args.robot)
    try:
        if not client.wait_for_controller(min(args.timeout, 15.0)):
            raise HilError.single(f"no hil control for robot '{args.robot}' is reachable",
                                  hint="start `hil control CONFIG` (or check --connect)")
        try:
            succeeded, message = client.reset_faults(args.timeout)
        except ControllerGone as exc:
            print(f"hil reset: {exc}", file=sys.stderr)
            return 1
        print(f"hil reset: {'done' if succeeded else 'failed'}: {message}",
              file=sys.stdout if succeeded else sys.stderr)
        return 0 if succeeded else 1
    finally:
        client.close()
        close_all()
