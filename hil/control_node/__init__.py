"""The controller process: hardware interface + controllers + the controller's faces, one
loop (:mod:`~hil.control_node.node`), and the fault reset it runs between cycles
(:mod:`~hil.control_node.fault_reset`)."""

from hil.control_node.fault_reset import RESET_TIMEOUT
from hil.control_node.node import ControlNode, FaceFactory

__all__ = ["RESET_TIMEOUT", "ControlNode", "FaceFactory"]
