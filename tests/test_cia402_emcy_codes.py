"""CiA 402's EMCY codes live in its own folder (issue 66 item 4): each fault of the drive
core has its code in CiA 402's table (CiA 301 table 21: 0x8130 heartbeat error, 0x8250
RPDO timeout, 0x9000 external error; CiA 402: 0x8611 following error, 0x8612 reference
limit), the core's Fault carries none, and the controller learns which codes mean a lost
link from the protocol's seam (Protocol.link_loss_codes), naming no CANopen number."""

from __future__ import annotations

import threading

from conftest import TEST_MOTOR_DRIVE
from test_cia402_files import drive_config

from hil.control_node.attribution import FaultAttribution
from hil.drives.core import DriveCore
from hil.drives.definitions import DriveParameters, Fault
from hil.protocols.cia402 import Cia402
from hil.protocols.cia402.drive import Cia402Drive
from hil.protocols.cia402.state import EMCY_CODES


def test_every_core_fault_has_its_emcy_code_in_the_cia402_table_and_none_in_the_core():
    assert set(EMCY_CODES) == set(Fault)
    assert EMCY_CODES[Fault.CONTROLLER_SILENT] == 0x8250
    assert EMCY_CODES[Fault.HEARTBEAT_LOST] == 0x8130
    assert not hasattr(Fault.FOLLOWING_ERROR, "code")


def test_the_controller_learns_the_link_loss_codes_from_the_protocols_seam():
    assert Cia402.link_loss_codes == {EMCY_CODES[Fault.CONTROLLER_SILENT],
                                      EMCY_CODES[Fault.HEARTBEAT_LOST]}
    assert FaultAttribution(0.002, 6).link_loss_codes >= Cia402.link_loss_codes


def test_a_cia402_drive_logs_its_fault_with_its_emcy_code():
    drive = Cia402Drive(drive_config(1), DriveCore(DriveParameters(**TEST_MOTOR_DRIVE)),
                        threading.Lock())
    assert (drive.fault_words(Fault.CONTROLLER_SILENT)
            == "setpoints stopped arriving (RPDO timeout) (0x8250)")
