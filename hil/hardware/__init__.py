"""Hardware interfaces: the CAN master for real (or virtual) drives, and a fake."""

from hil.compiled import COMPILED_AXES, import_fresh

# compiled by the install where it could be (setup.py): the axis seam with the MIT family's,
# Damiao's and CiA 402's axes, the cycle's exchange and the fault watch, one build whose
# modules call each other directly: all compiled or none, so they load together, here, before
# anything imports one
import_fresh(*COMPILED_AXES)

# the protocol modules loaded with the seam (above), named so that the import contracts see
# them (pyproject.toml, contract "protocol-seams")
import hil.protocols.cia402.axis  # noqa: E402,F401
import hil.protocols.damiao.axis  # noqa: E402,F401
import hil.protocols.mit.axis  # noqa: E402,F401
from hil.hardware.axis import AxisFault, FaultKind  # noqa: E402
from hil.hardware.bring_up import BOOT_TIMEOUT  # noqa: E402
from hil.hardware.can_interface import CanHardwareInterface  # noqa: E402
from hil.hardware.exchange import LOCK_STEP_REPLY_TIMEOUT, MISSED_ANSWER_LIMIT  # noqa: E402
from hil.hardware.feedback import JointFeedback  # noqa: E402
from hil.hardware.interface import FakeHardwareInterface, HardwareInterface  # noqa: E402

__all__ = ["AxisFault", "BOOT_TIMEOUT", "CanHardwareInterface", "FaultKind",
           "FakeHardwareInterface", "HardwareInterface", "JointFeedback",
           "LOCK_STEP_REPLY_TIMEOUT", "MISSED_ANSWER_LIMIT"]
