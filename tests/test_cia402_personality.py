"""A vendor's EDS as a simulated drive's personality, brought up by a third-party master.

Four real CiA 402 drives' EDS files (tests/eds/SOURCES.md) each become a drive of one bus
(``options: {eds: FILE}``). python canopen's master then does what a master configured from
the vendor's file does (ros2_canopen/Lely: boot-up, 0x1000 and 0x1018 checked against the
DCF, every configured value downloaded by SDO, PDOs mapped, NMT start; docs of ros2_canopen
and canopen's ``load_configuration``): the file made a DCF whose ParameterValue is each
writable object's DefaultValue, downloaded whole, the file's default PDO mapping read back,
then a move in the position mode the file offers (cyclic synchronous position where its
0x6502 has it and its target position is mappable, interpolated position otherwise)
through the plant.
"""

from __future__ import annotations

import math
import struct
import threading
import time
from pathlib import Path

import canopen
import pytest
from canopen.objectdictionary import NUMBER_TYPES, ODVariable

from conftest import UR3_VIRTUAL, CanopenBench, judged_in_real_time, patient

from hil.bus_config import load_bus_config
from hil.errors import HilError
from hil.protocols.cia402.node import normalise_access_types
from hil.protocols.cia402.ranges import RATES

EDS_DIR = Path(__file__).parent / "eds"
#: node id -> the vendor file that drive presents
VENDORS = {1: "technosoft_ipos.eds", 2: "schunk_prl120.eds", 3: "pilz_prbt.eds",
           4: "yiyou_euservo.eds"}
CYCLE = 0.01
CSP, IP = 8, 7


def _config(tmp_path: Path) -> Path:
    robot = (UR3_VIRTUAL.parent / "../../robots/ur3_description/urdf/ur3.xacro").resolve()
    drives = "\n".join(
        f"      - {{node_id: {node}, joint: joint{node}, options: {{eds: {EDS_DIR / name}}}}}"
        for node, name in VENDORS.items()) + (  # the rest hil's own drives
        "\n      - {node_id: 5, joint: joint5}\n      - {node_id: 6, joint: joint6}")
    path = tmp_path / "vendors.yaml"
    path.write_text(f"""robot: {robot}
plant_rate_hz: 1000
defaults: {{protocol: cia402, watchdog_timeout: 0.5}}
buses:
  - name: arm
    interface: virtual
    channel: vendors
    bitrate: 10000000
    cycle_hz: 100
    drives:
{drives}
""")
    return path


class VendorBench(CanopenBench):
    """The vendors' bus in a real-time Simulator, python canopen's master beside it."""

    def __init__(self, tmp_path: Path):
        super().__init__(_config(tmp_path))

    def master_of(self, node_id: int) -> canopen.RemoteNode:
        """A master's node from the vendor's file, made a DCF: each writable object's
        ParameterValue is its DefaultValue (the store commands aside, and a rate of 0 a
        file ships, as Yiyou's 0x6083-0x6085: the drive refuses it, hil.protocols.cia402.
        ranges.RATES, and a DCF for it configures the rates the axis needs)."""
        node = patient(canopen.RemoteNode(node_id, str(EDS_DIR / VENDORS[node_id])))
        normalise_access_types(node.object_dictionary)    # "RW" as a master reads it
        for entry in _variables(node.object_dictionary):
            # 0x1010/0x1011 are commands ("save", "load"), not values: a DCF leaves them out,
            # and a device aborts any other value written there (0x08000020)
            if entry.writable and entry.default is not None and entry.value is None \
                    and entry.index not in (0x1010, 0x1011) \
                    and not (entry.index in RATES and entry.default == 0):
                entry.value = entry.default
        self.network.add_node(node)
        return node

    def joint(self, node_id: int) -> float:
        with self.sim.lock:
            return float(self.sim.plant.joint_positions()[node_id - 1])


@pytest.fixture
def vendors(tmp_path, request):
    judged_in_real_time(request)
    bench = VendorBench(tmp_path)
    yield bench
    bench.close()


def _variables(od):
    for obj in od.values():
        if isinstance(obj, ODVariable):
            yield obj
        else:
            yield from (sub for sub in obj.values() if isinstance(sub, ODVariable))


def _in_file(entry: ODVariable) -> int | None:
    """What the file says an object holds: its ParameterValue (a DCF's), else DefaultValue."""
    return entry.value if entry.value is not None else entry.default


def _identity_matches_the_file(node) -> None:
    """0x1000 and 0x1018 as a Lely master checks them: each the file gives must match."""
    od = node.object_dictionary
    if _in_file(od[0x1000]) is not None:
        assert node.sdo[0x1000].raw == _in_file(od[0x1000])
    for sub in range(1, 5):
        if sub in od[0x1018].subindices and _in_file(od[0x1018][sub]) is not None:
            assert node.sdo[0x1018][sub].raw == _in_file(od[0x1018][sub])


def _file_mapping(od, mapping_index: int) -> list[int]:
    count = _in_file(od[mapping_index][0]) or 0
    return [_in_file(od[mapping_index][sub]) for sub in range(1, count + 1)]


def _move_rpdo(node, target: tuple[int, int]) -> int:
    """The COB-ID of an RPDO that maps the controlword then the position target, as the
    file maps them; RPDO1 remapped by SDO in the CiA 301 order where none does (as a Lely
    master does from its DCF: canopen's PdoMap.save writes no entries into a mapping
    parameter of object type ARRAY, as some vendors' files have it)."""
    wanted = [0x60400010, target[0] << 16 | target[1] << 8 | 32]
    for number in range(4):
        mapping, communication = 0x1600 + number, 0x1400 + number
        if mapping not in node.object_dictionary:
            continue
        cob_id = node.sdo[communication][1].raw
        count = node.sdo[mapping][0].raw
        entries = [node.sdo[mapping][sub].raw for sub in range(1, count + 1)]
        if entries == wanted and not cob_id & 0x80000000:
            return cob_id & 0x7FF
    cob_id = node.sdo[0x1400][1].raw & 0x7FF
    node.sdo[0x1400][1].raw = cob_id | 0x80000000        # not valid while it is remapped
    node.sdo[0x1600][0].raw = 0
    for sub, entry in enumerate(wanted, start=1):
        node.sdo[0x1600][sub].raw = entry
    node.sdo[0x1600][0].raw = len(wanted)
    node.sdo[0x1400][2].raw = 1                          # every SYNC
    node.sdo[0x1400][1].raw = cob_id
    return cob_id


@pytest.mark.parametrize("node_id", sorted(VENDORS), ids=lambda n: VENDORS[n][:-4])
def test_a_vendors_eds_is_the_drive_a_master_configures_from_that_file(vendors, node_id):
    node = vendors.master_of(node_id)
    od = node.object_dictionary
    booted = threading.Event()                 # the boot-up a master waits for
    vendors.network.subscribe(0x700 + node_id,
                              lambda can_id, data, ts: data[:1] == b"\0" and booted.set())
    node.nmt.send_command(0x81)                 # reset node
    assert booted.wait(5)
    _identity_matches_the_file(node)
    node.load_configuration()                   # every ParameterValue, PDOs first
    for number in range(4):                     # the file's default mapping, as downloaded
        for base in (0x1600, 0x1A00):
            if base + number in od:
                count = node.sdo[base + number][0].raw
                assert count == (_in_file(od[base + number][0]) or 0)
                assert [node.sdo[base + number][s].raw for s in range(1, count + 1)] == \
                    _file_mapping(od, base + number)
    offered = _in_file(od[0x6502]) if 0x6502 in od else None
    csp_offered = (not offered or offered >> (CSP - 1) & 1) and od[0x607A].pdo_mappable
    mode = CSP if csp_offered else IP
    target = (0x607A, 0) if mode == CSP else (0x60C1, 1)
    rpdo = _move_rpdo(node, target)
    node.sdo[0x6060].raw = mode
    node.nmt.send_command(0x01)
    drive = vendors.sim.drives[node_id - 1]
    counts_per_rad = drive.objects.counts_per_rad
    start = node.sdo[0x6064].raw
    goal = start + round(0.3 * counts_per_rad)           # 0.3 rad of the motor
    enable_ip = 0x10 if mode == IP else 0
    joint_before = vendors.joint(node_id)
    for step, word in enumerate([0x06] * 3 + [0x07] * 3 + [0x0F | enable_ip] * 80):
        value = start + (goal - start) * min(max(step - 6, 0), 50) // 50
        vendors.network.send_message(rpdo, struct.pack("<Hi", word, value))
        vendors.network.sync.transmit()
        time.sleep(CYCLE)
    assert node.sdo[0x6061].raw == mode
    assert node.sdo[0x6041].raw & 0x6F == 0x27           # operation enabled
    deadline = time.monotonic() + 5
    while abs(node.sdo[0x6064].raw - goal) > 0.01 * counts_per_rad and \
            time.monotonic() < deadline:
        vendors.network.send_message(rpdo, struct.pack("<Hi", 0x0F | enable_ip, goal))
        vendors.network.sync.transmit()
        time.sleep(CYCLE)
    assert abs(node.sdo[0x6064].raw - goal) <= 0.01 * counts_per_rad
    reduction = vendors.config.robot.reduction(
        vendors.config.buses[0].drives[node_id - 1].actuator)
    assert vendors.joint(node_id) - joint_before == pytest.approx(0.3 / reduction, rel=0.1)


@pytest.mark.parametrize("node_id", sorted(VENDORS), ids=lambda n: VENDORS[n][:-4])
def test_a_manufacturer_object_is_stored_with_its_access_type_and_range(vendors, node_id):
    node = vendors.master_of(node_id)
    od = node.object_dictionary
    manufacturer = [v for v in _variables(od) if 0x2000 <= v.index < 0x6000
                    and v.data_type in NUMBER_TYPES and v.data_type not in (0x01, 0x08, 0x11)]
    writable = next(v for v in manufacturer if v.writable and v.readable)
    low = writable.min if writable.min is not None else 0
    value = max(low, 0) + 1 if writable.max is None or writable.max > max(low, 0) else low
    sdo = (node.sdo[writable.index] if writable.subindex == 0 and isinstance(
        od[writable.index], ODVariable) else node.sdo[writable.index][writable.subindex])
    sdo.raw = value
    assert sdo.raw == value
    if writable.max is not None and writable.max < 2 ** (len(writable) - 1) - 1:
        with pytest.raises(canopen.SdoAbortedError) as refused:
            sdo.raw = writable.max + 1
        assert refused.value.code == 0x06090031          # value too high
    read_only = [v for v in manufacturer if not v.writable and v.readable]
    if read_only:
        entry = read_only[0]
        sdo = (node.sdo[entry.index] if isinstance(od[entry.index], ODVariable)
               else node.sdo[entry.index][entry.subindex])
        with pytest.raises(canopen.SdoAbortedError) as refused:
            sdo.raw = 0
        assert refused.value.code == 0x06010002          # attempt to write a read only object


def test_a_mode_the_vendors_file_does_not_offer_is_refused(vendors):
    node = vendors.master_of(1)                 # Technosoft iPOS: 0x6502 has no CSP
    with pytest.raises(canopen.SdoAbortedError) as refused:
        node.sdo[0x6060].raw = CSP
    assert refused.value.code == 0x06090030


def test_an_eds_that_is_no_drives_is_refused_with_the_file_named(tmp_path):
    config = _config(tmp_path)
    not_a_drive = tmp_path / "io.eds"
    not_a_drive.write_text("[DeviceInfo]\nVendorName=x\n[1000]\nParameterName=Device type\n"
                           "ObjectType=0x7\nDataType=0x0007\nAccessType=ro\n"
                           "DefaultValue=0x00000191\nPDOMapping=0\n")
    config.write_text(config.read_text().replace(str(EDS_DIR / VENDORS[1]), str(not_a_drive)))
    with pytest.raises(HilError) as refused:
        load_bus_config(config)
    message = str(refused.value)
    assert "io.eds" in message and "not a CiA 402 drive" in message


def test_hil_check_lists_the_objects_a_personality_stores_without_meaning(tmp_path):
    from hil.cli.check import bus_summary
    summary = bus_summary(load_bus_config(_config(tmp_path)))
    assert "personality yiyou_euservo.eds: Yiyou Technology EuServo" in summary
    assert "0x2001 " in summary                # a manufacturer-specific object of the file
    assert "0x6040 " not in summary            # the controlword has its meaning


@pytest.mark.parametrize("given, said", [
    ("/etc/passwd", "is no EDS, DCF or EPF"),
    ("5", "'eds' is the path of an EDS or DCF file, not 5"),
    ("missing.eds", "does not exist"),
])
def test_an_eds_option_that_names_no_eds_is_refused_without_echoing_the_file(tmp_path, given,
                                                                              said):
    config = _config(tmp_path)
    config.write_text(config.read_text().replace(str(EDS_DIR / VENDORS[1]), given))
    with pytest.raises(HilError) as refused:
        load_bus_config(config)
    assert said in str(refused.value) and "root:" not in str(refused.value)


def test_a_vendors_interpolation_period_of_0_is_taken_as_its_file_allows(vendors):
    """CiA 402 gives 0x60C2:01 (UNSIGNED8) its whole range and Technosoft's file no limits:
    a DCF's 0 is taken (it aborted with 0x06090032, hil's own limit over the file's); hil
    cannot time a period of 0, so the drive keeps the one it has."""
    node = vendors.master_of(1)
    drive = vendors.sim.drives[0]
    cycle = drive.core.cycle
    node.sdo[0x60C2][1].raw = 0
    assert node.sdo[0x60C2][1].raw == 0
    assert drive.core.cycle == cycle


def test_a_vendors_velocity_unit_0x60a9_gives_0x6080_and_0x607f_their_units(tmp_path):
    """CiA 402's SI unit velocity 0x60A9 (rpm: 0x00B44700, as Nanotec and Synapticon give
    it): the max motor speed 0x6080 a master writes from the file is rpm, not
    increments/s, and what the drive reports (0x607F) is in rpm too."""
    rpm_file = tmp_path / "rpm.eds"            # Yiyou's file (it has 0x607F), in rpm
    rpm_file.write_text((EDS_DIR / VENDORS[4]).read_text() + "".join(
        f"\n[{index}]\nParameterName={name}\nObjectType=0x7\nDataType=0x0007\n"
        f"AccessType=rw\nDefaultValue={default}\nPDOMapping=0\n"
        for index, name, default in (("60A9", "SI unit velocity", "0x00B44700"),
                                     ("6080", "Max motor speed", 1000))))
    config = _config(tmp_path)
    config.write_text(config.read_text().replace(str(EDS_DIR / VENDORS[4]), str(rpm_file)))
    bench = CanopenBench(config)
    try:
        node = patient(canopen.RemoteNode(4, str(rpm_file)))
        bench.network.add_node(node)
        drive = bench.sim.drives[3]
        top = drive.core.parameters.max_velocity                  # rad/s of the motor
        assert node.sdo[0x607F].raw == round(top * 60 / (2 * math.pi))
        node.sdo[0x6080].raw = 3000                                # rpm
        assert drive.core.parameters.max_velocity == pytest.approx(3000 * 2 * math.pi / 60)
    finally:
        bench.close()


@pytest.mark.parametrize("value, limits", [("nan", ""), ("inf", ""),
                                           ("200", "LowLimit=0\nHighLimit=100\n")])
def test_a_vendors_file_whose_own_value_its_object_does_not_take_is_refused(tmp_path, value,
                                                                            limits):
    """The drive starts with the file's values (a DCF's ParameterValue, else DefaultValue):
    one outside the object's limits, or a REAL32 that is not a finite number, would reach
    the drive unchecked, so the file is refused, the object named."""
    bad = tmp_path / "bad.dcf"
    bad.write_text((EDS_DIR / VENDORS[1]).read_text() + (
        f"\n[2FF0]\nParameterName=vendor gain\nObjectType=0x7\nDataType=0x0008\n"
        f"AccessType=rw\n{limits}DefaultValue=1\nParameterValue={value}\nPDOMapping=0\n"))
    config = _config(tmp_path)
    config.write_text(config.read_text().replace(str(EDS_DIR / VENDORS[1]), str(bad)))
    with pytest.raises(HilError) as refused:
        load_bus_config(config)
    assert "bad.dcf" in str(refused.value) and "0x2FF0" in str(refused.value)
