"""A node's ``/rosout``: hil's log records as rcl_interfaces/Log, as rcl publishes a node's
log lines."""

from __future__ import annotations

import logging
import sys

from hil.messaging import cdr
from hil.messaging.ros.interfaces import TypeHashes, distro_types
from hil.messaging.ros.node import RosNode
from hil.messaging.ros.rmw_zenoh import Durability, QoS
from hil.realtime.side_work import SideWorkQueue

#: rcl_qos_profile_rosout_default: reliable, transient local, keep last 1000
ROSOUT_QOS = QoS(durability=Durability.TRANSIENT_LOCAL, depth=1000)
#: rcl_interfaces/Log levels by Python's
LEVELS = {logging.DEBUG: 10, logging.INFO: 20, logging.WARNING: 30, logging.ERROR: 40,
          logging.CRITICAL: 50}
#: records waiting for the publishing thread; past this they are dropped and counted
BACKLOG = 1000


class RosoutHandler(logging.Handler):
    """Puts the records of the ``hil`` loggers at INFO and above on ``/rosout`` under the
    node's logger name (``<namespace>.<node>``, as rcl names it). Logging only queues the
    record, from any thread (the control loop's too); a thread of its own, at the side-work
    priority of a real-time process, encodes and puts it (:class:`SideWorkQueue`)."""

    def __init__(self, node: RosNode, hashes: TypeHashes, logger: str = "hil"):
        super().__init__(logging.INFO)
        self._types = distro_types(hashes.distro)
        self._name = ".".join([*node.namespace.strip("/").split("/"), node.name]).lstrip(".")
        self._publisher = node.publisher("/rosout", hashes.message("rcl_interfaces/msg/Log"),
                                         ROSOUT_QOS)
        self._log = self._types.types["rcl_interfaces/msg/Log"]
        self._work = SideWorkQueue(self._put, BACKLOG, "rosout")
        self._logger = logging.getLogger(logger)
        if not self._logger.hasHandlers():
            # Python prints WARNING and above to stderr only while no handler is installed:
            # keep doing so beside /rosout
            self._stderr = logging.StreamHandler(sys.stderr)
            self._stderr.setLevel(logging.WARNING)
            self._logger.addHandler(self._stderr)
        else:
            self._stderr = None
        self._level = self._logger.level
        self._logger.setLevel(min(self._logger.getEffectiveLevel(), logging.INFO))
        self._logger.addHandler(self)

    def emit(self, record: logging.LogRecord) -> None:
        self._work.put(record)

    def _put(self, record: logging.LogRecord) -> None:
        message = self._log(stamp=cdr.time_msg(record.created),
                            level=LEVELS.get(record.levelno, 20), name=self._name,
                            msg=record.getMessage(), file=record.pathname,
                            function=record.funcName, line=record.lineno)
        self._publisher.put(cdr.encode(message, self._types))

    def close(self) -> None:
        """Put what is queued, then stop and leave the logger as it was."""
        self._logger.removeHandler(self)
        if self._stderr is not None:
            self._logger.removeHandler(self._stderr)
        self._logger.setLevel(self._level)
        self._work.close(5.0)
        super().close()
