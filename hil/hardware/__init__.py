"""Hardware interfaces: the CAN master for real (or virtual) drives, and a fake."""

from hil.hardware.interface import (
    LOCK_STEP_REPLY_TIMEOUT, CanHardwareInterface, FakeHardwareInterface, HardwareInterface,
    JointFeedback,
)

__all__ = ["CanHardwareInterface", "FakeHardwareInterface", "HardwareInterface",
           "JointFeedback", "LOCK_STEP_REPLY_TIMEOUT"]
