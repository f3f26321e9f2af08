"""ODrive discovery (Address 0x06) and endpoint access (RxSdo 0x04 / TxSdo 0x05) from a
user's flat_endpoints.json, and the maker's own ``odrive`` library (0.6.11) over SocketCAN.

Sources: ODrive's CAN protocol page for firmware 0.6 (Address: node id and 48-bit serial
number, the Connection_ID from 0.6.11; RxSdo: opcode, endpoint id, reserved, value; TxSdo:
reserved, endpoint id, reserved, value), ODrive's DBC ``odrive-cansimple-0.6.10.dbc`` (in
``odrive-can``), ODrive's examples ``can_enumerate.py`` and ``can_param_access.py``
(ODriveResources: the flat_endpoints.json form, its fw_version/hw_version checked against
Get_Version), and the ``odrive`` library's frames as recorded over vcan (see
hil/protocols/odrive/sdo.py)."""

from __future__ import annotations

import asyncio
import ctypes.util
import json
import math
import struct
import time

import pytest

from conftest import TESTS, RealTimeMaster, socketcan_missing
from hil.bus_config import load_bus_config
from hil.errors import HilError
from hil.drives import Power
from hil.protocols.odrive import SERIAL_NUMBER_BASE, TURN, AxisState, Cmd, can_id
from hil.protocols.odrive.endpoints import crc16, json_id

pytestmark = pytest.mark.real_time

CONFIG = TESTS / "fixtures" / "odrive_one_axis.yaml"
ADDRESS_BROADCAST = can_id(0x3F, Cmd.ADDRESS)
OPCODE_READ, OPCODE_WRITE = 0, 1

#: a flat_endpoints.json of the form ODrive publishes for each release (the ids here are
#: this test's: a release assigns its own, which hil takes from the file)
ENDPOINTS = {
    "fw_version": "0.6.11", "hw_version": "4.4.58",
    "endpoints": {
        "hw_version_major": {"id": 1, "type": "uint8", "access": "r"},
        "hw_version_minor": {"id": 2, "type": "uint8", "access": "r"},
        "hw_version_variant": {"id": 3, "type": "uint8", "access": "r"},
        "fw_version_major": {"id": 4, "type": "uint8", "access": "r"},
        "fw_version_minor": {"id": 5, "type": "uint8", "access": "r"},
        "fw_version_revision": {"id": 6, "type": "uint8", "access": "r"},
        "commit_hash": {"id": 7, "type": "uint32", "access": "r"},
        "otp_valid": {"id": 8, "type": "bool", "access": "r"},
        "serial_number": {"id": 9, "type": "uint64", "access": "r"},
        "vbus_voltage": {"id": 10, "type": "float", "access": "r"},
        "axis0.current_state": {"id": 20, "type": "uint8", "access": "r"},
        "axis0.requested_state": {"id": 21, "type": "uint8", "access": "rw"},
        "axis0.active_errors": {"id": 22, "type": "uint32", "access": "r"},
        "axis0.pos_estimate": {"id": 23, "type": "float", "access": "r"},
        "axis0.controller.config.control_mode": {"id": 30, "type": "uint8", "access": "rw"},
        "axis0.controller.config.input_mode": {"id": 31, "type": "uint8", "access": "rw"},
        "axis0.controller.config.vel_integrator_limit": {"id": 32, "type": "float",
                                                         "access": "rw"},
        "axis0.controller.input_pos": {"id": 33, "type": "float", "access": "rw"},
        "clear_errors": {"id": 40, "type": "function", "inputs": [], "outputs": []},
    }}
UNBACKED = 32            # vel_integrator_limit: in the file, not simulated


def _config(tmp_path, endpoints=ENDPOINTS):
    """The one-axis ODrive config with ``endpoints`` as its flat_endpoints.json."""
    (tmp_path / "flat_endpoints.json").write_text(
        endpoints if isinstance(endpoints, str) else json.dumps(endpoints))
    config = tmp_path / "odrive.yaml"
    robot = TESTS / "fixtures" / "one_axis.urdf"
    config.write_text(CONFIG.read_text()
                      .replace("robot: one_axis.urdf", f"robot: {robot}")
                      .replace("{node_id: 0, joint: yaw}",
                               "{node_id: 0, joint: yaw, options: "
                               "{endpoints: flat_endpoints.json, encoder_msg_rate_ms: 0}}"))
    return config


@pytest.fixture
def master(tmp_path, hil_drives):
    return RealTimeMaster(hil_drives(_config(tmp_path)))


def _sdo(master, opcode: int, endpoint: int, value: bytes = b"", sequence: int = 0x10,
         connection: int = 0):
    """An RxSdo and the TxSdo answer (None: none within 0.5 s)."""
    header = bytes([connection | opcode]) + endpoint.to_bytes(2, "little") + bytes([sequence])
    reply = master.ask(can_id(0, Cmd.RX_SDO), header + value, timeout=0.5,
                      answer_id=can_id(0, Cmd.TX_SDO))
    return None if reply is None else bytes(reply.data)


def test_the_broadcast_address_rtr_is_answered_with_node_serial_and_connection(master):
    """can_enumerate.py's discovery: an RTR on node 63's Address id; the answer carries the
    node id, the serial number (6 bytes, LE) and, from 0.6.11, a non-zero Connection_ID
    (libodrive finds one with 0 not connectable and ignores a 7-byte one)."""
    reply = master.ask(ADDRESS_BROADCAST, remote=True, answer_id=can_id(0, Cmd.ADDRESS))
    assert reply is not None and len(reply.data) == 8
    assert reply.data[0] == 0
    assert int.from_bytes(reply.data[1:7], "little") == SERIAL_NUMBER_BASE
    assert reply.data[7] != 0


def test_the_address_answer_and_the_txsdo_decode_with_odrives_dbc(master):
    """The DBC (0.6.10) spells Address as Node_ID (byte 0) and Serial_Number (bytes 1-6),
    TxSdo as Reserved0, Endpoint_ID, Reserved1, Value; an RTR on the node's own Address id
    is answered too."""
    import importlib.resources

    import cantools
    dbc = cantools.database.load_file(
        str(importlib.resources.files("odrive_can") / "dbc" / "odrive-cansimple-0.6.10.dbc"))
    reply = master.ask(can_id(0, Cmd.ADDRESS), remote=True, answer_id=can_id(0, Cmd.ADDRESS))
    address = dbc.get_message_by_name("Axis0_Address").decode(bytes(reply.data))
    assert (address["Node_ID"], address["Serial_Number"]) == (0, SERIAL_NUMBER_BASE)
    answer = _sdo(master, OPCODE_READ, 10)                       # vbus_voltage
    sdo = dbc.get_message_by_name("Axis0_TxSdo").decode(answer, decode_choices=False)
    assert sdo["Endpoint_ID"] == 10
    assert struct.unpack("<f", answer[4:8])[0] == pytest.approx(24.0)


def test_discovery_frames_are_told_as_the_masters_to_every_odrive():
    from hil.can.frame import Frame
    from hil.protocols.odrive import ODrive
    for remote in (True, False):
        source = ODrive.frame_source(Frame(ADDRESS_BROADCAST, remote=remote), {0: object()})
        assert (source.sender.value, source.node_id) == ("master", None)
    answer = ODrive.frame_source(Frame(can_id(0, Cmd.ADDRESS), bytes(8)), {0: object()})
    assert (answer.sender.value, answer.node_id) == ("drive", 0)


def test_a_connect_frame_for_this_serial_gives_the_drive_the_clients_connection_id(master):
    serial = SERIAL_NUMBER_BASE.to_bytes(6, "little")
    master.ask(ADDRESS_BROADCAST, bytes([0]) + serial + bytes([0x78]), timeout=0.1)
    reply = master.ask(ADDRESS_BROADCAST, remote=True, answer_id=can_id(0, Cmd.ADDRESS))
    assert reply.data[7] == 0x78


def test_endpoint_zero_serves_the_descriptor_and_its_fibre_version_id(master):
    """The odrive library's get_json_id (offset 0xFFFFFFFF) and get_json (4 bytes an offset,
    a shorter answer at the end); the answers repeat the request's first and fourth bytes."""
    answer = _sdo(master, OPCODE_READ, 0, b"\xff\xff\xff\xff", sequence=0x30, connection=0x14)
    assert answer[:4] == bytes([0x14, 0, 0, 0x30])
    version_id = int.from_bytes(answer[4:], "little")
    descriptor = b""
    while True:
        chunk = _sdo(master, OPCODE_READ, 0, len(descriptor).to_bytes(4, "little"))[4:]
        descriptor += chunk
        if len(chunk) < 4:
            break
    assert version_id == json_id(descriptor) and version_id >> 16 == crc16(1, descriptor)
    tree = {item["name"]: item for item in json.loads(descriptor)}
    axis0 = {item["name"]: item for item in tree["axis0"]["members"]}
    assert axis0["requested_state"] == {"name": "requested_state", "id": 21,
                                        "type": "uint8", "access": "rw"}
    assert tree["clear_errors"]["type"] == "function"


def test_get_version_gives_the_endpoints_files_versions(master):
    """can_param_access.py asserts the file's fw_version and hw_version against Get_Version."""
    reply = master.ask(can_id(0, Cmd.GET_VERSION), remote=True,
                      answer_id=can_id(0, Cmd.GET_VERSION))
    assert tuple(reply.data[1:7]) == (4, 4, 58, 0, 6, 11)


def test_endpoints_read_and_write_as_the_can_commands_of_the_same_meaning(master):
    """requested_state is Set_Axis_State, input_pos is Set_Input_Pos; writes are confirmed
    (from 0.6.11) with the header alone."""
    assert _sdo(master, OPCODE_WRITE, 21, bytes([AxisState.CLOSED_LOOP_CONTROL])) \
        == bytes([OPCODE_WRITE, 21, 0, 0x10])
    assert _sdo(master, OPCODE_READ, 20)[4] == AxisState.CLOSED_LOOP_CONTROL
    _sdo(master, OPCODE_WRITE, 33, struct.pack("<f", 0.5))
    time.sleep(1.0)
    position = struct.unpack("<f", _sdo(master, OPCODE_READ, 23)[4:8])[0]
    assert position == pytest.approx(0.5, abs=0.01)
    assert position * TURN / 10 == pytest.approx(master.joint(), abs=2e-3)


@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_an_input_pos_write_of_nan_or_inf_is_refused_and_moves_nothing(master, value):
    _sdo(master, OPCODE_WRITE, 21, bytes([AxisState.CLOSED_LOOP_CONTROL]))
    time.sleep(0.3)
    before = master.joint()
    assert _sdo(master, OPCODE_WRITE, 33, struct.pack("<f", value)) is None
    time.sleep(0.3)
    assert master.joint() == pytest.approx(before, abs=2e-3)


def test_closed_loop_by_endpoint_is_refused_while_errors_stand_as_set_axis_state_is(master):
    master.ask(can_id(0, Cmd.ESTOP), timeout=0.2)
    _sdo(master, OPCODE_WRITE, 21, bytes([AxisState.CLOSED_LOOP_CONTROL]))
    assert _sdo(master, OPCODE_READ, 20)[4] == AxisState.IDLE
    assert master.drive.core.power is not Power.ENABLED
    _sdo(master, OPCODE_WRITE, 40)                                # clear_errors()
    _sdo(master, OPCODE_WRITE, 21, bytes([AxisState.CLOSED_LOOP_CONTROL]))
    assert _sdo(master, OPCODE_READ, 20)[4] == AxisState.CLOSED_LOOP_CONTROL


@pytest.mark.parametrize("endpoint", [UNBACKED, 9, 999], ids=["unbacked", "uint64", "unknown"])
def test_endpoints_hil_does_not_back_are_not_answered(master, endpoint):
    assert _sdo(master, OPCODE_READ, endpoint) is None
    assert _sdo(master, OPCODE_WRITE, endpoint, struct.pack("<f", 1.0)) is None


@pytest.mark.parametrize("content, says", [
    ("{not json", "not JSON"),
    (json.dumps({"fw_version": "0.6.11", "hw_version": "4.4.58"}), "no 'endpoints'"),
    (json.dumps({**ENDPOINTS, "fw_version": "six"}), "'fw_version'"),
    (json.dumps({**ENDPOINTS, "endpoints": {"a": {"id": 1, "type": "complex"}}}),
     "unknown type 'complex'"),
    (json.dumps({**ENDPOINTS, "endpoints": {"a": {"id": 1, "type": "float"},
                                            "b": {"id": 1, "type": "float"}}}),
     "share id 1")])
def test_a_bad_endpoints_file_is_refused_naming_the_file(tmp_path, content, says):
    with pytest.raises(HilError) as refused:
        load_bus_config(_config(tmp_path, content))
    message = str(refused.value)
    assert "flat_endpoints.json" in message and says in message


@pytest.mark.socketcan
def test_the_makers_odrive_library_discovers_and_moves_the_axis_over_socketcan(
        tmp_path, monkeypatch):
    """``odrive`` 0.6.11 (libodrive 0.9.6): find_async on ``can:vcan0`` (Address discovery,
    connect, the descriptor read over endpoint 0), then closed loop and a position through
    the endpoints, as odrivetool's user does."""
    missing = socketcan_missing()
    if missing:
        pytest.skip(missing)
    if ctypes.util.find_library("usb-1.0") is None:
        pytest.fail("the odrive library's libodrive links libusb-1.0: install Debian's "
                    "libusb-1.0-0 (.ci/run does)")
    import odrive
    from odrive.device_manager import close_device_manager
    # the library caches descriptors under $XDG_CACHE_HOME: this test's, so it reads ours
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    master = RealTimeMaster.of(_config(tmp_path), vcan="vcan0")

    async def session():
        try:
            odrv = await asyncio.wait_for(odrive.find_async(interfaces=["can:vcan0"]), 60)
            await odrv.axis0.controller.config.control_mode.write(3)  # POSITION_CONTROL
            await odrv.axis0.controller.config.input_mode.write(1)    # PASSTHROUGH
            await odrv.axis0.requested_state.write(AxisState.CLOSED_LOOP_CONTROL)
            await odrv.axis0.controller.input_pos.write(0.5)
            await asyncio.sleep(1.5)
            state = await odrv.axis0.current_state.read()
            position = await odrv.axis0.pos_estimate.read()
            await odrv.axis0.requested_state.write(AxisState.IDLE)
            return odrv, state, position
        finally:
            # its discovery (an Address RTR a second) stops with it: the tests after this
            # one share vcan0
            close_device_manager()

    try:
        odrv, state, position = asyncio.run(session())
        assert odrv._dev.serial_number == f"{SERIAL_NUMBER_BASE:012X}"
        assert state == AxisState.CLOSED_LOOP_CONTROL
        assert position == pytest.approx(0.5, abs=0.01)
        assert position * TURN / 10 == pytest.approx(master.joint(), abs=2e-3)
    finally:
        master.close()


def test_a_serial_number_is_48_bits_as_the_address_message_carries():
    from hil.protocols.odrive import ODriveOptions
    assert ODriveOptions.from_mapping({"serial_number": 2**48 - 1}).serial_number == 2**48 - 1
    for bad in (2**48, -1, "0x12", True):
        with pytest.raises(ValueError, match="48 bits"):
            ODriveOptions.from_mapping({"serial_number": bad})


def test_node_63_is_refused_as_the_broadcast_and_unaddressed_id(tmp_path):
    config = _config(tmp_path)
    config.write_text(config.read_text().replace("{node_id: 0, joint: yaw", "{node_id: 63, joint: yaw"))
    with pytest.raises(HilError, match="node id 63 is outside 0..62"):
        load_bus_config(config)
