"""controller_manager on ROS 2: the node ``controller_manager`` in the face's namespace with
its ``list_controllers`` and ``switch_controller`` services (controller_manager_msgs, as
``ros2 control list_controllers`` and ``switch_controllers`` call them), and each forward
command controller's ``<controller>/commands`` subscription (std_msgs/Float64MultiArray, the
topic forward_command_controller subscribes as ``~/commands``; declared by this node)."""

from __future__ import annotations

import logging
import time

from hil.controllers.manager import ControllerManager
from hil.messaging import cdr
from hil.messaging.controller_manager import (
    forward_command, list_response, switch_response,
)
from hil.messaging.ros.interfaces import TypeHashes
from hil.messaging.ros.node import RosContext, RosNode, ServiceRequest

log = logging.getLogger(__name__)

NODE = "controller_manager"
#: a refused command is logged at most this often per controller (a stream runs at 100 Hz)
REFUSAL_LOG_PERIOD = 1.0


class RosControllerManager:
    """Serves ``manager`` on ROS 2 through ``context``."""

    def __init__(self, context: RosContext, namespace: str, manager: ControllerManager,
                 hashes: TypeHashes):
        self.manager = manager
        self.node = RosNode(context, NODE, namespace)
        self.node.service(f"{NODE}/list_controllers",
                          hashes.service("controller_manager_msgs/srv/ListControllers"),
                          self._on_list)
        self.node.service(f"{NODE}/switch_controller",
                          hashes.service("controller_manager_msgs/srv/SwitchController"),
                          self._on_switch)
        commands = hashes.message(cdr.FLOAT64_MULTI_ARRAY)
        self._last_refusal: dict[str, float] = {}
        for name in manager.forward_names():
            self.node.subscription(f"{name}/commands", commands,
                                   lambda payload, _, name=name: self._on_command(name, payload))

    def _on_list(self, request: ServiceRequest) -> None:
        request.reply(list_response(self.manager))

    def _on_switch(self, request: ServiceRequest) -> None:
        try:
            request.reply(switch_response(self.manager, request.payload))
        except ValueError as exc:
            request.reply_error(str(exc))

    def _on_command(self, name: str, payload: bytes) -> None:
        try:
            forward_command(self.manager, name, payload)
        except ValueError as exc:
            now = time.monotonic()
            if now - self._last_refusal.get(name, -REFUSAL_LOG_PERIOD) >= REFUSAL_LOG_PERIOD:
                self._last_refusal[name] = now
                log.warning("command refused: %s", exc)

    def close(self) -> None:
        self.node.close()
