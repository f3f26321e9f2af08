"""``hil reset ROBOT``: reset drive faults of a running hil control, and accept goals again."""

from __future__ import annotations

import argparse
import sys

from hil.cli import common
from hil.errors import UsageError
from hil.messaging.zenoh_api import ControllerGone, TrajectoryActionClient
from hil.zenoh_session import close_all, session


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("robot", nargs="?", help="robot name, e.g. ur3 (none with --ros)")
    parser.add_argument("--timeout", type=common.duration, default=15.0, metavar="TIME",
                        help="how long to wait, e.g. 15s (default 15s)")
    common.add_zenoh(parser, "operator")
    common.add_ros(parser, "call a std_srvs/Trigger service on ROS 2 (rmw_zenoh) instead: "
                           "hil control --ros serves <namespace>/hil_control/reset_faults")
    parser.add_argument("--service", metavar="NAME",
                        help="with --ros: the Trigger service to call (default "
                             "hil_control/reset_faults in --ros-namespace)")


def run(args: argparse.Namespace) -> int:
    settings = common.ros_settings(args)
    if settings is not None:
        if args.robot is not None:
            raise UsageError.single(f"with --ros, give no robot name ({args.robot})",
                                    hint="hil reset --ros [--service NAME]")
        return _reset_ros(args, settings)
    if args.robot is None:
        raise UsageError.single("give the robot's name", hint="hil reset ur3")
    common.robot_name(args.robot)
    zenoh = common.zenoh_settings(args)
    client = TrajectoryActionClient(session(zenoh), args.robot)
    try:
        if not client.wait_for_controller(min(args.timeout, 15.0)):
            raise common.no_controller(zenoh, args.robot)
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


def _reset_ros(args: argparse.Namespace, settings) -> int:
    """Call a std_srvs/Trigger service (hil control --ros' fault reset by default)."""
    from hil.messaging import cdr                                        # noqa: PLC0415
    from hil.messaging.ros.face import reset_service_name                # noqa: PLC0415
    from hil.messaging.ros.interfaces import TypeHashes                  # noqa: PLC0415
    from hil.messaging.ros.node import ServiceError                     # noqa: PLC0415
    from hil.messaging.ros.rmw_zenoh import fully_qualified              # noqa: PLC0415
    name = (fully_qualified(settings.namespace, args.service) if args.service
            else reset_service_name(settings))
    with common.ros_node(settings, "hil_reset", name, min(args.timeout, 15.0),
                         hint="start `hil control CONFIG --ros` (or check --service)") as node:
        client = node.client(name, TypeHashes(settings.distro).service("std_srvs/srv/Trigger"))
        try:
            payload, _ = client.call(cdr.EMPTY_REQUEST, args.timeout)
            response = cdr.decode(payload, cdr.TRIGGER_RESPONSE)
        except (ServiceError, ValueError) as exc:
            print(f"hil reset: {exc}", file=sys.stderr)
            return 1
    print(f"hil reset: {'done' if response.success else 'failed'}: {response.message}",
          file=sys.stdout if response.success else sys.stderr)
    return 0 if response.success else 1
