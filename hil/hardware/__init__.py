"""Hardware interfaces: the CAN master for real (or virtual) drives, and a fake."""

from hil.hardware.axis import AxisFault, FaultKind
from hil.hardware.bring_up import BOOT_TIMEOUT
from hil.hardware.can_interface import CanHardwareInterface
from hil.hardware.exchange import LOCK_STEP_REPLY_TIMEOUT, MISSED_ANSWER_LIMIT
from hil.hardware.feedback import JointFeedback
from hil.hardware.interface import FakeHardwareInterface, HardwareInterface

__all__ = ["AxisFault", "BOOT_TIMEOUT", "CanHardwareInterface", "FaultKind",
           "FakeHardwareInterface", "HardwareInterface", "JointFeedback",
           "LOCK_STEP_REPLY_TIMEOUT", "MISSED_ANSWER_LIMIT"]
