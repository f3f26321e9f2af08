"""What rclcpp gives every node besides its own endpoints: its parameters
(:mod:`~hil.messaging.ros.parameters`), its log on ``/rosout``
(:mod:`~hil.messaging.ros.rosout`) and the descriptions of the types it uses
(:mod:`~hil.messaging.ros.type_descriptions`). ``ros2 param``, ``rqt`` and MoveIt ask
for the first, ``ros2 topic echo /rosout`` and rqt_console read the second, tools built
for another distribution ask for the third."""

from __future__ import annotations

import time
from collections.abc import Callable

from hil.messaging.ros.interfaces import TypeHashes
from hil.messaging.ros.node import RosNode
from hil.messaging.ros.parameters import Parameter, ParameterServer, Value
from hil.messaging.ros.rosout import RosoutHandler
from hil.messaging.ros.type_descriptions import TypeDescriptionService


class NodeServices:
    """The standard services of ``node``; ``apply`` and ``ros_time`` as
    :class:`ParameterServer` takes them (log lines carry the wall clock, as rcutils stamps
    them whatever the node's clock)."""

    def __init__(self, node: RosNode, hashes: TypeHashes, parameters: list[Parameter],
                 apply: Callable[[dict[str, Value]], None] | None = None,
                 ros_time: Callable[[], float] = time.time):
        self.parameters = ParameterServer(node, hashes, parameters, apply, ros_time)
        self.type_descriptions = TypeDescriptionService(node, hashes)
        self.rosout = RosoutHandler(node, hashes)

    def close(self) -> None:
        self.rosout.close()
        self.parameters.close()
        self.type_descriptions.close()
