"""Hardware interfaces: the CAN master for real (or virtual) drives, and a fake."""

from hil.hardware.axis import AxisFault, FaultKind
from hil.hardware.feedback import JointFeedback
from hil.hardware.can_interface import (BOOT_TIMEOUT, LOCK_STEP_REPLY_TIMEOUT, MISSED_ANSWER_LIMIT,
                                         CanHardwareInterface)
from hil.hardware.interface import FakeHardwareInterface, HardwareInterface

__all__ = ["AxisFault", "BOOT_TIMEOUT", "CanHardwareInterface", "FaultKind",
           "FakeHardwareInterface", "HardwareInterface", "JointFeedback",
           "LOCK_STEP_REPLY_TIMEOUT", "MISSED_ANSWER_LIMIT"]
