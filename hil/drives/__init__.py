"""Simulated servo drives: the protocol-free core and the seam to a protocol.

The drives of each protocol live with it (``hil.protocols.<name>.drive``), found through
:func:`hil.protocols.protocol`.
"""

from hil.compiled import import_fresh

# compiled by the install where it could be (setup.py): the core, its references and the
# CiA 402 device, one build (compiled modules of one build call each other directly: all or
# none)
import_fresh("hil.drives.definitions", "hil.drives.references", "hil.drives.core",
             "hil.drives.group", "hil.protocols.cia402.state")

from hil.drives.core import DriveCore  # noqa: E402
from hil.drives.definitions import DriveParameters, DriveStatus, Fault, Mode, Power  # noqa: E402
from hil.drives.profile import DriveProfile  # noqa: E402

__all__ = ["DriveCore", "DriveParameters", "DriveProfile", "DriveStatus", "Fault", "Mode",
           "Power"]
