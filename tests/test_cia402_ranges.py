"""What a hil CiA 402 drive takes into its objects, and what it records of its errors.

Every write a master or a file makes is checked against what the drive takes before it
reaches the motor (CiA 301 7.2.4.3.17 abort codes 0x06090030 value range exceeded,
0x06090031 too high, 0x06090032 too low): the EDS's LowLimit/HighLimit (CiA 306), else the
data type's range; hil's own gains 0x2000 finite within the limits its EDS declares; no
rate of 0 where a stop must decelerate (CiA 402 0x6083-0x6085). EMCYs of frames the drive
could not take are recorded in 0x1003 and 0x1001 (CiA 301 7.5.2.1, 7.5.2.3).
"""

from __future__ import annotations

import configparser
import json
import math
import struct
import time

import pytest

from conftest import EDS
from test_cia402_conformance import abort_code, pre_operational, raw, wait_until
from test_cia402_drive import emcy_logged_after, enable_csp

from hil.protocols.cia402.node import DriveNode
from hil.protocols.cia402.personality import Personality
from hil.protocols.cia402.storage import ParameterStore
from hil.resources import eds_path

#: how far a holding joint may drift meanwhile (rad): the position loop's own settling
HOLD = 1e-3


def _joint(bench) -> float:
    with bench.sim.lock:
        return float(bench.sim.plant.joint_positions()[0])


def _expedited(node, index, sub, data):
    node.sdo.download(index, sub, data)


def _segmented(node, index, sub, data):
    node.sdo.download(index, sub, data, force_segment=True)


def _block(node, index, sub, data):
    with node.sdo.open(index, sub, "wb", size=len(data), block_transfer=True) as stream:
        stream.write(data)


@pytest.mark.parametrize("value, code", [(math.nan, 0x06090030), (math.inf, 0x06090031),
                                         (-math.inf, 0x06090032), (-1.0, 0x06090032),
                                         (1e12, 0x06090031)])
def test_a_gain_out_of_its_limits_is_refused_on_every_sdo_path_and_the_axis_holds(
        canopen_bench, value, code):
    """A gain of NaN once drove a holding motor to full torque (3.7 rad to the following
    error fault): every SDO path refuses it, and the axis stays where it stood."""
    node = enable_csp(canopen_bench)
    time.sleep(0.2)
    drive = canopen_bench.sim.drive("arm", 1)
    gains = drive.core.parameters
    before = _joint(canopen_bench)
    data = struct.pack("<f", value)
    for path in (_expedited, _segmented, _block):
        for sub in (1, 2, 3):
            assert abort_code(lambda: path(node, 0x2000, sub, data)) == code, (path, sub)
    time.sleep(0.3)
    after = drive.core.parameters
    assert (after.position_kp, after.velocity_kp, after.velocity_ki) == (
        gains.position_kp, gains.velocity_kp, gains.velocity_ki)
    assert abs(_joint(canopen_bench) - before) < HOLD


def test_hils_eds_declares_the_gains_limits_and_that_it_is_an_lss_slave():
    """CiA 306: LowLimit/HighLimit of what the drive takes; LSS_Supported=1 for a CiA 305
    slave (hil.protocols.cia402.lss)."""
    eds = configparser.ConfigParser()
    eds.read(EDS)
    for sub in (1, 2, 3):
        section = eds[f"2000sub{sub}"]
        assert float(section["LowLimit"]) == 0
        assert math.isfinite(float(section["HighLimit"]))
    assert eds["DeviceInfo"]["LSS_Supported"] == "1"


def test_a_parameter_file_value_the_object_does_not_take_is_not_restored(tmp_path):
    kept = tmp_path / "drive1.json"
    kept.write_text(json.dumps({"2000:01": struct.pack("<f", math.nan).hex(),
                                "2000:02": struct.pack("<f", 0.5).hex(),
                                "1017:00": (250).to_bytes(2, "little").hex()}))
    node = DriveNode(1, Personality.of(None).dictionary(1))
    default = node.object_dictionary[0x2000][1].default
    ParameterStore(kept).restore(node, communication_only=False)
    assert node.value(0x2000, 1) == pytest.approx(default)     # NaN refused, default kept
    assert node.value(0x2000, 2) == pytest.approx(0.5)
    assert node.value(0x1017) == 250


@pytest.mark.parametrize("index", [0x6083, 0x6084, 0x6085])
def test_a_rate_of_0_is_refused_and_a_quick_stop_still_stops(canopen_bench, index):
    """0x6085 = 0 once left a quick stop and the watchdog's stop without deceleration (the
    axis went on at 1 rad/s for 3 s): refused with 0x06090032, the configured rate stays."""
    node = enable_csp(canopen_bench)
    time.sleep(0.2)
    drive = canopen_bench.sim.drive("arm", 1)
    before = drive.core.parameters
    assert abort_code(lambda: node.sdo.download(index, 0, bytes(4))) == 0x06090032
    assert drive.core.parameters == before
    joint = _joint(canopen_bench)
    node.controlword = 0x02                                  # quick stop
    assert wait_until(lambda: node.state == "QUICK STOP ACTIVE")
    time.sleep(0.3)
    assert abs(_joint(canopen_bench) - joint) < HOLD


def test_frame_errors_are_recorded_in_0x1003_and_0x1001_as_their_emcy_says(canopen_bench):
    """CiA 301 7.5.2.3: 0x1003 holds the errors signalled by EMCY, newest first; 7.5.2.1:
    0x1001 the register the EMCY carried (0x11: generic, communication) while the error is
    in force; a frame of its kind that comes right ends it (EMCY 0x0000, register 0)."""
    node = pre_operational(canopen_bench)
    node.nmt.state = "OPERATIONAL"
    raw(canopen_bench, 0x080, b"\x01")       # a SYNC with a counter: 0x1019 is 0
    assert emcy_logged_after(node, 0x8240)
    raw(canopen_bench, 0x201, b"\x00")       # RPDO1 shorter than its mapping (6 bytes)
    assert emcy_logged_after(node, 0x8210, 0x8240)
    assert [e.register for e in node.emcy.log if e.code in (0x8240, 0x8210)] == [0x11, 0x11]
    assert node.sdo[0x1003][0].raw == 2
    assert [node.sdo[0x1003][sub].raw for sub in (1, 2)] == [0x8210, 0x8240]
    assert node.sdo[0x1001].raw == 0x11
    raw(canopen_bench, 0x080, b"")           # the SYNC right again: 0x8210 still in force
    assert wait_until(lambda: [e.code for e in node.emcy.log][-1:] == [0x0000])
    assert node.sdo[0x1001].raw == 0x11
    raw(canopen_bench, 0x201, struct.pack("<Hi", 0x0006, 0))  # the RPDO right again: none left
    assert wait_until(lambda: [e.code for e in node.emcy.log][-2:] == [0x0000, 0x0000])
    assert node.emcy.log[-1].register == 0
    assert node.sdo[0x1001].raw == 0
    assert node.sdo[0x1003][0].raw == 2      # the history stays until a master clears it


def test_software_position_limits_of_0_and_0_are_no_limits(canopen_bench):
    """Makers' convention (Novanta/Ingenia EMCL and Summit 0x607D: both 0 disables the
    limits; Kollmorgen AKD: default 0, switched off)."""
    node = pre_operational(canopen_bench)
    drive = canopen_bench.sim.drive("arm", 1)
    node.sdo[0x607D][1].raw = 0
    node.sdo[0x607D][2].raw = 0
    assert drive.core.parameters.position_limits is None
    node.sdo[0x607D][2].raw = 1000
    assert drive.core.parameters.position_limits == pytest.approx(
        (0.0, 1000 / drive.objects.counts_per_rad))


def test_a_following_error_window_of_0_is_no_window_and_only_ffffffff_switches_it_off(
        canopen_bench):
    """CiA 402 0x6065: FFFFFFFFh switches the following control off; 0 is a window of no
    width (it switched hil's following error fault off)."""
    node = pre_operational(canopen_bench)
    drive = canopen_bench.sim.drive("arm", 1)
    node.sdo[0x6065].raw = 0
    assert drive.core.parameters.following_error_limit > 0
    node.sdo[0x6065].raw = 0xFFFFFFFF
    assert drive.core.parameters.following_error_limit == 0      # the core's "off"


def test_a_rate_of_0_an_rpdo_carries_is_not_taken_and_raises_nothing(canopen_bench):
    """An RPDO that maps 0x6084 cannot be answered with an abort (CiA 301): its 0 is dropped,
    as CANopenNode drops a PDO's write its object dictionary refuses; it once raised in the
    bus' receiving thread."""
    drive = canopen_bench.sim.drive("arm", 1)
    before = drive.core.parameters
    with canopen_bench.sim.lock:
        drive.objects.set_profile_parameter(0x6084, 0)       # what _apply does for an RPDO
    assert drive.core.parameters == before
