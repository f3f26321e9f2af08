"""Hardware interfaces: the CAN master for real (or virtual) drives, and a fake."""

from hil.hardware.interface import (
    CanHardwareInterface, FakeHardwareInterface, HardwareInterface, JointFeedback,
)

__all__ = ["CanHardwareInterface", "FakeHardwareInterface", "HardwareInterface",
           "JointFeedback"]
