"""Simulated servo drives: the protocol-free core and the seam to a protocol.

The drives of each protocol live with it (``hil.protocols.<name>.drive``), found through
:func:`hil.protocols.protocol`.
"""

from hil.compiled import COMPILED, import_fresh

# compiled by the install where it could be (setup.py): the core, its references, the profile
# seam, the CiA 402 state machine and drive and the MIT family's and Damiao's motors, one
# build whose modules call each other directly: all compiled or none, so they load together,
# here, before anything imports one of them
import_fresh(*COMPILED)

# the protocol modules loaded with the core (above), named so that the import contracts see
# them (pyproject.toml, contract "protocol-seams")
import hil.protocols.cia402.drive  # noqa: E402,F401
import hil.protocols.cia402.pdo  # noqa: E402,F401
import hil.protocols.cia402.rpdo  # noqa: E402,F401
import hil.protocols.cia402.state  # noqa: E402,F401
import hil.protocols.cia402.tpdo  # noqa: E402,F401
import hil.protocols.damiao.drive  # noqa: E402,F401
import hil.protocols.mit.drive  # noqa: E402,F401
from hil.drives.core import DriveCore  # noqa: E402
from hil.drives.definitions import DriveParameters, DriveStatus, Fault, Mode, Power  # noqa: E402
from hil.drives.profile import DriveProfile  # noqa: E402

__all__ = ["DriveCore", "DriveParameters", "DriveProfile", "DriveStatus", "Fault", "Mode",
           "Power"]
