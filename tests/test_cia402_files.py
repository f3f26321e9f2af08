"""A CiA 402 drive's files as hostile input (issue 65 items 7, 8, 9, 13): a vendor's EDS,
DCF or EPF and the parameter file are read within bounds and checked where ``hil check``
runs (the bus config's reading: :meth:`Cia402.drive_problem`), so the drive ``hil sim``
starts never meets what the check passed; what is refused is a message naming the file.

CiA 306 (the EDS: an INI file, ASCII, its data types CiA 301's), CiA 301 7.3.5 (restricted
CAN-IDs; CANopenNode's CO_IS_RESTRICTED_CAN_ID), 7.5.2.35-38 (PDO parameters).
"""

from __future__ import annotations

import json
import os
import re
import threading
import uuid
from pathlib import Path

import can
import pytest

from conftest import EDS, TEST_MOTOR_DRIVE

from hil.bus_config.types import DriveConfig
from hil.can.router import start_router
from hil.drives.core import DriveCore
from hil.drives.definitions import DriveParameters
from hil.errors import HilError
from hil.protocols.cia402 import Cia402, Cia402Options
from hil.protocols.cia402.drive import Cia402Drive


def edited(folder: Path, changes: dict[str, dict[str, str]], name: str = "drive.eds",
           text: str | None = None) -> Path:
    """hil's own EDS with ``changes``: section -> {key: value} (a key set or added)."""
    text = text if text is not None else EDS.read_text()
    for section, keys in changes.items():
        for key, value in keys.items():
            block = re.compile(rf"(^\[{section}\]\n(?:(?!\[).*\n)*?){key}=.*\n", re.MULTILINE)
            if block.search(text):
                text = block.sub(lambda m: f"{m.group(1)}{key}={value}\n", text, count=1)
            else:
                text = text.replace(f"[{section}]\n", f"[{section}]\n{key}={value}\n", 1)
    path = folder / name
    path.write_text(text)
    return path


def checked(node_id: int = 1, **options) -> str | None:
    """What ``hil check`` says of a drive with these options (None: nothing)."""
    try:
        given = Cia402Options.from_mapping({key: str(value) for key, value in options.items()})
    except ValueError as exc:
        return str(exc)
    return Cia402.drive_problem(node_id, given)


def drive_config(node_id: int, options: Cia402Options | None = None) -> DriveConfig:
    """A CiA 402 drive's config, TEST_MOTOR_DRIVE's ratings, a heartbeat every 0.1 s."""
    motor = TEST_MOTOR_DRIVE
    return DriveConfig(
        node_id=node_id, actuator="motor", joints=("joint",), protocol="cia402",
        encoder_counts_per_rev=motor["counts_per_rev"], rated_torque=motor["rated_torque"],
        peak_torque=motor["peak_torque"], max_velocity=motor["max_velocity"],
        following_error_limit=motor["following_error_limit"],
        following_error_timeout=motor["following_error_timeout"],
        quick_stop_deceleration=motor["quick_stop_deceleration"],
        watchdog_timeout=motor["watchdog_timeout"], heartbeat_period=0.1,
        holding_brake=True, position_limits=motor["position_limits"], gains=None,
        velocity_bandwidth_hz=0.0, options=options)


def started(node_id: int = 1, **options) -> Cia402Drive:
    """The drive ``hil sim`` starts with these options, on a bus of its own."""
    given = Cia402Options.from_mapping({key: str(value) for key, value in options.items()})
    drive = Cia402Drive(drive_config(node_id, given),
                        DriveCore(DriveParameters(**TEST_MOTOR_DRIVE)), threading.Lock())
    bus = can.Bus(interface="virtual", channel=f"files-{uuid.uuid4().hex}")
    router = start_router(bus, keep_sending=True)
    try:
        drive.attach(router)
        drive.detach()
    finally:
        router.stop()
        bus.shutdown()
    return drive


# --- item 7: data types and values -----------------------------------------------------

@pytest.mark.parametrize("changes, named", [
    ({"6502": {"DataType": "0x0009"}}, "0x6502"),              # supported modes as a string
    ({"6076": {"DataType": "0x0009"}}, "0x6076"),              # rated torque as a string
    ({"1400sub1": {"DataType": "0x0009"}}, "0x1400 sub-index 1"),   # RPDO1's COB-ID
    ({"608Fsub1": {"DataType": "0x0005"}}, "0x608F sub-index 1"),   # increments, UNSIGNED8
    ({"6041": {"DataType": "0x0009"}}, "0x6041"),              # statusword
    ({"6064": {"DataType": "0x0009"}}, "0x6064"),              # position actual value
    ({"1000": {"DataType": "0x0009"}}, "0x1000"),              # device type
    ({"1600sub0": {"DefaultValue": "0xFF"}}, "0x1600"),        # 255 mapped objects
    ({"1400sub1": {"DefaultValue": "0x80"}}, "0x1400:01"),     # RPDO1 on the SYNC's id
    ({"1800sub1": {"DefaultValue": "0x701"}}, "0x1800:01"),    # a heartbeat's id
    ({"2000sub1": {"DataType": "0x000C"}}, "TIME_OF_DAY"),     # a type hil does not model
], ids=lambda v: str(v)[:40])
def test_an_eds_object_of_a_type_or_value_the_drive_cannot_run_with_is_refused_at_check(
        tmp_path, changes, named):
    """CiA 301/402 give these objects their data types (hil's own EDS has them), CiA 301
    7.5.2.36 a mapping of at most 64 entries, 7.3.5 the restricted CAN-IDs: ``hil check``
    names the file and the object, where it passed them and ``hil sim`` died."""
    said = checked(eds=edited(tmp_path, changes))
    assert said is not None and "drive.eds" in said and named in said, said
    assert "unsupported operand" not in said


def test_an_eds_in_windows_1252_is_read(tmp_path):
    """CiA 306 says ASCII; vendors' tools write their Windows code page: a name with
    'é' and '°' in cp1252 (Latin-1's printable part) is read, where it was refused whole."""
    text = EDS.read_text().replace("ParameterName=Device type",
                                   "ParameterName=Type d'appareil (é, 90°)")
    path = tmp_path / "latin.eds"
    path.write_bytes(text.encode("cp1252"))
    assert checked(eds=path) is None
    assert started(eds=path).node.object_dictionary[0x1000].name == "Type d'appareil (é, 90°)"


def test_an_eds_byte_no_common_encoding_decodes_is_named_with_its_line(tmp_path):
    path = tmp_path / "odd.eds"
    data = EDS.read_bytes().replace(b"ParameterName=Device type",
                                    b"ParameterName=Device \x81type")
    path.write_bytes(data)
    line = data[:data.index(b"\x81")].count(b"\n") + 1
    said = checked(eds=path)
    assert said is not None and f"line {line}" in said and "0x81" in said


# --- item 8: bounds ----------------------------------------------------------------------

def test_an_eds_over_the_size_bound_is_refused_unread(tmp_path):
    """A sparse file of 4 GB gave MemoryError: the size is read before a byte is."""
    path = tmp_path / "huge.eds"
    with open(path, "wb") as file:
        file.truncate(4 * 1024 ** 3)
    said = checked(eds=path)
    assert said is not None and "huge.eds" in said and "over the" in said


def test_an_eds_of_too_many_objects_is_refused_before_it_is_parsed(tmp_path):
    """A million objects took ``hil check`` 52 s and 2.8 GB: the sections are counted."""
    sections = "".join(f"[{0x3000 + i:04X}]\nParameterName=x\nObjectType=0x7\n"
                       f"DataType=0x0005\nAccessType=rw\nDefaultValue=0\n"
                       for i in range(10_000))
    path = tmp_path / "many.eds"
    path.write_text(EDS.read_text() + sections)
    said = checked(eds=path)
    assert said is not None and "sections" in said and "many.eds" in said


def test_an_epf_with_a_document_type_is_refused_before_its_entities_expand(tmp_path):
    """An XML entity bomb ended in a ParseError traceback: no DOCTYPE is read (hil's
    input_files, as defusedxml's forbid_dtd)."""
    path = tmp_path / "bomb.epf"
    path.write_text('<?xml version="1.0"?>\n<!DOCTYPE lolz [<!ENTITY lol "lol">'
                    '<!ENTITY lol2 "&lol;&lol;&lol;&lol;&lol;&lol;&lol;&lol;">]>\n'
                    '<Root>&lol2;</Root>\n')
    said = checked(eds=path)
    assert said is not None and "bomb.epf" in said and "DOCTYPE" in said


@pytest.mark.parametrize("key", ["eds", "parameter_file"])
def test_a_path_with_a_name_over_255_bytes_is_refused_without_a_traceback(tmp_path, key):
    said = checked(**{key: tmp_path / ("x" * 300 + ".eds")})
    assert said is not None and "255" in said


# --- item 9: the parameter file ----------------------------------------------------------

@pytest.mark.parametrize("content, named", [
    ({"6081:00": 5}, "6081:00"),                               # not a string
    ({"1017:00": "e80300"}, "0x1017:00"),                      # 3 bytes for an UNSIGNED16
    ({"1019:00": "0000"}, "0x1019:00"),                        # 2 bytes for an UNSIGNED8
    ({"1600:00": "40"}, "0x1600"),                             # 64 mapped, 8 entries
    ({"1400:01": "81020080"}, None),                           # 0x281, not valid: taken
    ({"1400:01": "80000000"}, "0x1400:01"),                    # 0x80: the SYNC's id
    ({"1400:01": "ffff0000"}, "0x1400:01"),                    # bits 11-28 of an 11-bit id
    ({"1400:01": "01070000"}, "0x1400:01"),                    # 0x701: a heartbeat's id
    ({"2000:01": "00"}, "0x2000:01"),                          # 1 byte for a REAL32
    ({"7777:00": "00"}, "0x7777:00"),                          # no such object
    ({"x": "00"}, "'x'"),                                      # no index:sub
], ids=lambda v: str(v)[:30])
def test_a_parameter_file_value_the_drive_does_not_take_is_refused_at_check(tmp_path, content,
                                                                            named):
    """CiA 301: 0x1017 UNSIGNED16, 0x1019 UNSIGNED8, a mapping of at most its entries,
    7.3.5's restricted CAN-IDs for a valid PDO; each refused by ``hil check`` with the file
    and the value named (they were a TypeError, ObjectDictionaryError, KeyError at start,
    or taken); the drive itself starts, the value not restored."""
    kept = tmp_path / "kept.json"
    kept.write_text(json.dumps(content))
    said = checked(parameter_file=kept)
    if named is None:
        assert said is None
        return
    assert said is not None and "kept.json" in said and named in said, said
    if not isinstance(next(iter(content.values())), str) or named == "'x'":
        return
    drive = started(parameter_file=kept)
    assert drive.node.value(0x1600, 0) == 2 and drive.node.value(0x1400, 1) == 0x201


def test_a_parameter_file_nested_deep_is_refused_without_recursing(tmp_path):
    kept = tmp_path / "deep.json"
    kept.write_text("[" * 200_000 + "]" * 200_000)
    said = checked(parameter_file=kept)
    assert said is not None and "deep.json" in said and "nested" in said


def test_a_parameter_file_of_more_keys_than_a_drive_has_is_refused(tmp_path):
    """A million keys took 24 s to start: a drive has some hundred parameters."""
    kept = tmp_path / "many.json"
    kept.write_text(json.dumps({f"{0x3000 + i // 256:04X}:{i % 256:02X}": "00"
                                for i in range(5000)}))
    said = checked(parameter_file=kept)
    assert said is not None and "5000 values" in said


@pytest.mark.parametrize("kind", ["fifo", "device"])
def test_a_parameter_file_that_is_no_regular_file_is_refused_unread(tmp_path, kind):
    """A FIFO hung the start, /dev/zero filled the memory."""
    if kind == "fifo":
        kept = tmp_path / "kept.json"
        os.mkfifo(kept)
    else:
        kept = Path("/dev/zero")
    said = checked(parameter_file=kept)
    assert said is not None and "not a regular file" in said


def test_a_parameter_file_hil_wrote_is_taken(tmp_path):
    kept = tmp_path / "kept.json"
    kept.write_text(json.dumps({"1017:00": (250).to_bytes(2, "little").hex()}))
    assert checked(parameter_file=kept) is None
    assert started(parameter_file=kept).node.value(0x1017) == 250


# --- item 13: the pytest fixture ---------------------------------------------------------

def test_the_hil_drives_fixture_with_a_bad_eds_is_a_hil_error_naming_the_file(tmp_path,
                                                                               hil_drives):
    """It was a TypeError from the simulator's start: the bus config's reading refuses
    the file now, as ``hil check`` does."""
    from test_cia402_personality import _config, EDS_DIR, VENDORS

    bad = edited(tmp_path, {"6502": {"DataType": "0x0009"}}, "bad.eds")
    config = _config(tmp_path)
    config.write_text(config.read_text().replace(str(EDS_DIR / VENDORS[1]), str(bad)))
    with pytest.raises(HilError) as refused:
        hil_drives(config)
    assert "bad.eds" in str(refused.value) and "0x6502" in str(refused.value)
