"""``hil router``: a Zenoh router with rmw_zenohd's settings, for hosts without ROS 2."""

from __future__ import annotations

import argparse
import signal
import threading

import zenoh

from hil.cli import common
from hil.errors import ProcessError
from hil.messaging.ros.router import DEFAULT_LISTEN, open_router


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--listen", action="append", default=[], metavar="ENDPOINT",
                        help=f"endpoint to listen on (repeatable; default {DEFAULT_LISTEN}, "
                             "rmw_zenohd's: every interface)")


def run(args: argparse.Namespace) -> int:
    listen = tuple(args.listen) or (DEFAULT_LISTEN,)
    try:
        router = open_router(listen)
    except zenoh.ZError as exc:
        raise ProcessError.single(f"cannot start a Zenoh router on {', '.join(listen)}: {exc}",
                                  hint="is a router (rmw_zenohd, zenohd, hil router) already "
                                       "running there? choose another with --listen") from None
    stop = threading.Event()
    previous = common.on_stop_signals(stop.set)
    print(f"hil router: Zenoh router {router.zid()} listening on {', '.join(listen)} "
          "(rmw_zenohd's settings); Ctrl-C stops it", flush=True)
    try:
        while not stop.wait(0.5):     # a timed wait: signals reach the main thread
            pass
    finally:
        router.close()
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    print("hil router: stopped", flush=True)
    return 0
