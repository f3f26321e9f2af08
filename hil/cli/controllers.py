"""``hil controllers ROBOT``: list a running hil control's controllers, or switch them as
controller_manager's switch_controller does (``ros2 control switch_controllers``)."""

from __future__ import annotations

import argparse
import sys

from hil.cli import common
from hil.controllers.manager import Strictness
from hil.messaging.controller_manager import ControllerManagerClient
from hil.messaging.zenoh_api import ProcessWatch
from hil.zenoh_session import close_all, session


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("robot", help="robot name, e.g. ur3")
    parser.add_argument("--activate", nargs="+", default=[], metavar="NAME",
                        help="controllers to activate")
    parser.add_argument("--deactivate", nargs="+", default=[], metavar="NAME",
                        help="controllers to deactivate (first, in the same switch)")
    parser.add_argument("--best-effort", action="store_true",
                        help="switch what can be switched (default: strict, all or nothing)")
    parser.add_argument("--timeout", type=common.duration, default=5.0, metavar="TIME",
                        help="how long to wait for the controller (default 5s)")
    common.add_zenoh(parser, "operator")


def run(args: argparse.Namespace) -> int:
    common.robot_name(args.robot)
    zenoh = common.zenoh_settings(args)
    # the controller first, as `hil send` and `hil reset` wait for it: with none, the same
    # error, saying why where the session reached nobody (the queries themselves are asked
    # again while they meet no one: hil.messaging.keys.ask)
    watch = ProcessWatch(session(zenoh), args.robot)
    client = ControllerManagerClient(session(zenoh), args.robot, args.timeout)
    try:
        if not watch.wait_alive("control", args.timeout):
            raise common.no_controller(zenoh, args.robot)
        if args.activate or args.deactivate:
            ok, message = client.switch(args.activate, args.deactivate,
                                        Strictness.BEST_EFFORT if args.best_effort
                                        else Strictness.STRICT)
            # (controller_manager ends each line of a best-effort refusal with a newline)
            message = message.rstrip("\n")
            print(f"hil controllers: {'switched' if ok else 'refused'}"
                  + (f": {message}" if message else ""),
                  file=sys.stdout if ok else sys.stderr)
            if not ok:
                return 1
        for state in client.list():
            print(f"{state.name:32} {state.type:56} {state.state}")
        return 0
    except TimeoutError as exc:
        print(f"hil controllers: {exc}", file=sys.stderr)
        return 1
    finally:
        watch.close()
        close_all()
