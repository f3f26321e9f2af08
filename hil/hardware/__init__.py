"""Hardware interfaces: the CAN master for real (or virtual) drives, and a fake."""

from hil.compiled import COMPILED_MASTER, import_fresh

# the master's build (setup.py), loaded before anything imports one of its modules
import_fresh(*COMPILED_MASTER)

from hil.hardware.axis import AxisFault, FaultKind  # noqa: E402
from hil.hardware.bring_up import BOOT_TIMEOUT  # noqa: E402
from hil.hardware.can_interface import CanHardwareInterface  # noqa: E402
from hil.hardware.exchange import LOCK_STEP_REPLY_TIMEOUT, MISSED_ANSWER_LIMIT  # noqa: E402
from hil.hardware.feedback import JointFeedback  # noqa: E402
from hil.hardware.interface import FakeHardwareInterface, HardwareInterface  # noqa: E402

__all__ = ["AxisFault", "BOOT_TIMEOUT", "CanHardwareInterface", "FaultKind",
           "FakeHardwareInterface", "HardwareInterface", "JointFeedback",
           "LOCK_STEP_REPLY_TIMEOUT", "MISSED_ANSWER_LIMIT"]
