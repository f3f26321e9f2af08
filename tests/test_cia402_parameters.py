"""A drive's parameters over SDO: store and restore (CiA 301 7.5.2.13, 7.5.2.14: 0x1010,
0x1011), kept across a reset within the run and, with ``parameter_file``, across restarts;
the position factor (CiA 402 0x6091, 0x6092) and the max motor speed 0x6080."""

from __future__ import annotations

import math
import time
import uuid
from pathlib import Path

import can
import pytest

from conftest import UR3_VIRTUAL, CanopenBench
from test_cia402_conformance import abort_code, pre_operational, wait_until

from hil.bus_config import load_bus_config
from hil.errors import HilError
from hil.realtime import REAL_TIME
from hil.simulator import Simulator

SAVE, LOAD = b"save", b"load"          # 0x65766173, 0x64616F6C as the bytes go on the bus
APPLICATION, ALL = 3, 1


def _reset_node(bench, node) -> None:
    node.nmt.send_command(0x81)
    assert wait_until(lambda: node.nmt.state == "PRE-OPERATIONAL")
    time.sleep(0.1)


@pytest.mark.wire("a reset node seen from another socket")
def test_saved_application_parameters_come_back_after_a_reset_node(canopen_bench):
    node = pre_operational(canopen_bench)
    configured = node.sdo[0x6065].raw
    assert node.sdo[0x1010][APPLICATION].raw == 1          # saves on command
    node.sdo[0x6065].raw = configured + 1000
    node.sdo.download(0x1010, APPLICATION, SAVE)
    node.sdo[0x6065].raw = configured + 2000               # not saved
    _reset_node(canopen_bench, node)
    assert node.sdo[0x6065].raw == configured + 1000
    node.sdo.download(0x1011, APPLICATION, LOAD)           # the defaults at the next reset
    _reset_node(canopen_bench, node)
    assert node.sdo[0x6065].raw == configured


def test_a_store_command_without_its_signature_is_aborted(canopen_bench):
    node = pre_operational(canopen_bench)
    assert abort_code(lambda: node.sdo.download(0x1010, ALL, b"nope")) == 0x08000020
    assert abort_code(lambda: node.sdo.download(0x1011, ALL, SAVE)) == 0x08000020


def test_process_data_is_not_saved(canopen_bench):
    node = pre_operational(canopen_bench)
    node.sdo[0x607A].raw = 12345                           # a target: PDO-mappable
    node.sdo.download(0x1010, ALL, SAVE)
    _reset_node(canopen_bench, node)
    assert node.sdo[0x607A].raw != 12345


@pytest.fixture
def kept_config(tmp_path) -> Path:
    text = UR3_VIRTUAL.read_text().replace("../../robots", str(UR3_VIRTUAL.parents[2] / "robots"))
    text = text.replace("{node_id: 1, joint: joint1}",
                        "{node_id: 1, joint: joint1, options: {parameter_file: drive1.json}}")
    path = tmp_path / "kept.yaml"
    path.write_text(text)
    return path


def test_a_parameter_file_keeps_what_was_saved_across_restarts(kept_config):
    bench = CanopenBench(kept_config)
    try:
        node = pre_operational(bench)
        configured = node.sdo[0x6065].raw
        node.sdo[0x6065].raw = configured + 777
        node.sdo.download(0x1010, ALL, SAVE)
    finally:
        bench.close()
    assert (kept_config.parent / "drive1.json").is_file()
    bench = CanopenBench(kept_config)
    try:
        assert pre_operational(bench).sdo[0x6065].raw == configured + 777
    finally:
        bench.close()


def test_a_parameter_file_hil_did_not_write_is_refused_with_its_name(kept_config):
    (kept_config.parent / "drive1.json").write_text("[1, 2")
    bus = can.Bus(interface="virtual", channel=f"store-{uuid.uuid4().hex}")
    try:
        with pytest.raises(HilError) as refused:
            Simulator(load_bus_config(kept_config), {"arm": bus}, REAL_TIME)
    finally:
        bus.shutdown()
    assert "drive1.json" in str(refused.value)


def test_the_position_factor_sets_the_units_of_positions_and_velocities(canopen_bench):
    """CiA 402 6.3.1: user units per motor revolution = feed constant 0x6092 / gear ratio
    0x6091; by default one revolution's encoder increments."""
    node = pre_operational(canopen_bench)
    increments = node.sdo[0x6092][1].raw
    assert increments == node.sdo[0x608F][1].raw and node.sdo[0x6091][1].raw == 1
    before = node.sdo[0x6064].raw
    node.sdo[0x6091][1].raw = 2                 # 2 motor revolutions per shaft revolution
    node.sdo[0x6092][1].raw = 1000              # 1000 units per shaft revolution
    drive = canopen_bench.sim.drive("arm", 1)
    assert drive.objects.counts_per_rad == pytest.approx(500 / (2 * math.pi))
    # the unpowered axis may creep a few increments meanwhile: 1 unit is 262 of them
    assert node.sdo[0x6064].raw == pytest.approx(before * 500 / increments, abs=3)
    assert abort_code(lambda: node.sdo.download(0x6091, 2, bytes(4))) == 0x06090032
    _reset_node(canopen_bench, node)            # the defaults again
    assert drive.objects.counts_per_rad == pytest.approx(increments / (2 * math.pi))


def test_the_max_motor_speed_0x6080_limits_the_velocity(canopen_bench):
    node = pre_operational(canopen_bench)
    top = node.sdo[0x6080].raw
    assert top == node.sdo[0x607F].raw > 0
    node.sdo[0x6080].raw = top // 2
    drive = canopen_bench.sim.drive("arm", 1)
    assert drive.core.parameters.max_velocity == pytest.approx(
        top // 2 / drive.objects.counts_per_rad)
