"""Virtual servo drives: a protocol-free core behind a drive profile.

:data:`PROFILES` picks the profile class by the ``protocol`` string of a bus
config, the way python-can picks an interface.
"""

from hil.compiled import import_fresh

# compiled by the install where it could be (setup.py)
import_fresh("hil.drives.core", "hil.drives.cia402_state")

from hil.drives.cia402 import Cia402Drive
from hil.drives.mit import MitDrive
from hil.drives.odrive import ODriveDrive
from hil.drives.core import DriveCore, DriveParameters, DriveStatus, Fault, Mode, Power
from hil.drives.profile import DriveProfile

#: protocol name -> drive class
PROFILES = {profile.protocol: profile for profile in (Cia402Drive, MitDrive, ODriveDrive)}

__all__ = ["Cia402Drive", "DriveCore", "DriveParameters", "DriveProfile", "DriveStatus",
           "Fault", "MitDrive", "Mode", "ODriveDrive", "PROFILES", "Power"]
