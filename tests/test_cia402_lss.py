"""LSS (CiA 305): a master finds drives that boot without a node id and assigns them one.

The master is python canopen's LssMaster (fastscan, configure node id, store, switch
state global; switch state selective and the inquire services), over python-can's
in-process bus; the drives are hil's, two of them at node id 255 (unconfigured) with
distinct serial numbers (0x1018:04). Each case cites CiA 305 as CANopenNode's
CO_LSSslave.c implements it.
"""

from __future__ import annotations

import time
from pathlib import Path

import canopen
import pytest

from conftest import UR3_VIRTUAL, CanopenBench
from test_cia402_conformance import FrameTap, wait_until
from test_cia402_drive import enable_csp

from hil.bus_config import load_bus_config
from hil.errors import HilError
from hil.testing import DrivesBench

#: judged against the host's stalls (tests/host_stalls.py): the drives run in real time beside
#: canopen's LSS master
pytestmark = pytest.mark.real_time

SERIALS = {"joint1": 1, "joint2": 2}


def _config(tmp_path: Path, first: str = "{node_id: 255, joint: joint1, "
                                        "options: {serial_number: 1}}") -> Path:
    text = UR3_VIRTUAL.read_text().replace("../../robots", str(UR3_VIRTUAL.parents[2] / "robots"))
    text = text.replace("{node_id: 1, joint: joint1}", first)
    text = text.replace("{node_id: 2, joint: joint2}",
                        "{node_id: 255, joint: joint2, options: {serial_number: 2}}")
    path = tmp_path / "lss.yaml"
    path.write_text(text)
    return path


@pytest.fixture
def unconfigured(tmp_path):
    bench = CanopenBench(_config(tmp_path))
    yield bench
    bench.close()


def _assign(network: canopen.Network, node_id: int) -> list[int]:
    """Fastscan one unconfigured drive, give it ``node_id``, store it, let it boot."""
    found, identity = network.lss.fast_scan()
    assert found, "no unconfigured drive answered the fastscan"
    network.lss.configure_node_id(node_id)
    network.lss.store_configuration()
    network.lss.send_switch_state_global(network.lss.WAITING_STATE)
    return identity


def test_drives_without_a_node_id_send_nothing_until_assigned(unconfigured):
    with FrameTap(unconfigured) as tap:
        time.sleep(0.5)
    own = {0x700 + n for n in range(3, 7)}
    assert {msg.arbitration_id for msg in tap.frames if msg.arbitration_id >= 0x700} == own


def test_an_lss_master_assigns_node_ids_by_fastscan_and_brings_the_drives_up(unconfigured):
    network = unconfigured.network
    with FrameTap(unconfigured) as tap:
        first = _assign(network, 1)
        second = _assign(network, 2)
        time.sleep(0.3)
    # the lowest identity first (CiA 305 fastscan): serial 1, then 2; vendor, product,
    # revision as hil's EDS gives them
    assert first == [0, 402, 2, 1] and second == [0, 402, 2, 2]
    assert [m.data[0] for m in tap.of(0x701)][:1] == [0x00]       # boot-up with its new id
    assert [m.data[0] for m in tap.of(0x702)][:1] == [0x00]
    assert network.lss.fast_scan() == (False, None)                # none left unconfigured
    for node_id in (1, 2):
        node = enable_csp(unconfigured, node_id)
        assert node.state == "OPERATION ENABLED"
        assert node.sdo[0x1018][4].raw == node_id                  # its serial number


def test_switch_state_selective_and_inquire_services(unconfigured):
    lss = unconfigured.network.lss
    _assign(unconfigured.network, 1)
    lss.send_switch_state_selective(0, 402, 2, 2)                  # the other drive (0x44)
    assert lss.inquire_node_id() == 255
    assert lss.inquire_lss_address(canopen.lss.CS_INQUIRE_SERIAL_NUMBER) == 2
    assert lss.inquire_lss_address(canopen.lss.CS_INQUIRE_PRODUCT_CODE) == 402
    lss.configure_node_id(7)
    with pytest.raises(canopen.lss.LssError):                      # 128: out of range
        lss.configure_node_id(128)
    lss.send_switch_state_global(lss.WAITING_STATE)
    node = enable_csp(unconfigured, 7)
    assert node.state == "OPERATION ENABLED"


def _answers(bench, ask) -> list[int]:
    """The command specifiers of the LSS answers (0x7E4) to what ``ask`` sends
    (canopen's identify services do not wait for answers)."""
    with FrameTap(bench) as tap:
        ask()
        time.sleep(0.3)
    return [msg.data[0] for msg in tap.of(0x7E4)]


def test_identify_services_are_answered_by_the_drives_they_describe(unconfigured):
    lss = unconfigured.network.lss
    # identify non-configured remote slave: 0x50 from each drive without a node id
    assert _answers(unconfigured, lss.send_identify_non_configured_remote_slave) == [0x50] * 2
    # identify remote slave: vendor, product, revision range, serial range: 0x4F from each
    # drive within them (the configured ones have the EDS's serial 0, outside 2..2)
    within = _answers(unconfigured, lambda: lss.send_identify_remote_slave(0, 402, 0, 9, 2, 2))
    assert within == [0x4F]
    assert _answers(unconfigured, lambda: lss.send_identify_remote_slave(0, 401, 0, 9, 0, 9)) == []
    _assign(unconfigured.network, 1)
    _assign(unconfigured.network, 2)
    assert _answers(unconfigured, lss.send_identify_non_configured_remote_slave) == []


def test_an_unconfigured_drive_without_a_serial_number_is_refused(tmp_path):
    config = _config(tmp_path, first="{node_id: 255, joint: joint1}")
    with pytest.raises(HilError) as refused:
        load_bus_config(config)
    assert "serial_number" in str(refused.value)


def _states(bench, node_id: int) -> list[str]:
    with bench.sim.lock:
        return [drive.node.nmt.state for drive in bench.sim.drives if drive.node_id == node_id]


@pytest.mark.parametrize("command, target", [(0x01, 1), (0x01, 0), (0x02, 1), (0x02, 0)],
                         ids=["start node", "start all", "stop node", "stop all"])
def test_two_drives_given_one_node_id_both_stay_on_the_bus(tmp_path, caplog, command, target):
    """CiA 305 configure node id answers only 'out of range' (error 1): the drive cannot
    know the ids of the others (CANopenNode's CO_LSSslave.c takes any 1-127). A master
    that gives a taken id makes two nodes of one id, as on a real bus: both answer NMT and
    both send on the id's COB-IDs (their frames collide where a master can see it). The
    drive that took the id replaced the other in canopen's node dictionary, which then
    heard no NMT at all. The simulator says so (a warning) where a bus shows collisions."""
    bench = CanopenBench(_config(
        tmp_path, "{node_id: 1, joint: joint1, options: {serial_number: 1}}"))
    try:
        lss = bench.network.lss
        found, _ = lss.fast_scan()                     # the one without a node id
        assert found
        lss.configure_node_id(1)                       # taken: answered 0 all the same
        lss.send_switch_state_global(lss.WAITING_STATE)
        assert wait_until(lambda: _states(bench, 1) == ["PRE-OPERATIONAL"] * 2)
        assert "node id 1 given by LSS is another drive's too" in caplog.text
        with FrameTap(bench) as tap:
            bench.network.send_message(0x000, bytes([command, target]))
            want = "OPERATIONAL" if command == 0x01 else "STOPPED"
            assert wait_until(lambda: _states(bench, 1) == [want] * 2), _states(bench, 1)
            time.sleep(0.5)
        beats = [msg.data[0] for msg in tap.of(0x701)]
        assert beats.count(0x05 if command == 0x01 else 0x04) >= 2   # from each drive
    finally:
        bench.close()


@pytest.fixture
def lss_bench(tmp_path):
    """A drives-only bench of the two drives that boot without a node id, and a canopen
    network (its LssMaster) on its bus."""
    with DrivesBench(_config(tmp_path)) as bench:
        network = canopen.Network(bench.bus("arm"))
        network.connect()
        yield bench, network
        network.disconnect()


def test_the_bench_names_the_drives_lss_gave_ids_by_their_joints(lss_bench):
    """CiA 305: a drive takes the id configure node id gave it at its next reset; the bench's
    state() and fault() name it by its joint (its config entry), not by the config's 255."""
    bench, network = lss_bench
    _assign(network, 7)                                            # serial 1: joint1
    _assign(network, 8)
    assert wait_until(lambda: [bench.state(joint).split()[0] for joint in SERIALS]
                      == ["PRE-OPERATIONAL"] * 2)
    bench.fault("joint2")
    assert bench.state("joint2").endswith("FAULT")
    assert not bench.state("joint1").endswith("FAULT")
    assert bench.sim.drive("arm", 8) is bench.sim.configured(bench.drive("joint2").config)


def test_a_node_id_lss_gave_two_drives_is_refused_by_id_and_named_by_joint(tmp_path):
    """Two drives on one id (test_two_drives_given_one_node_id_both_stay_on_the_bus): a
    lookup by that id would silently get one of them; it says which joints share it and
    what to do, and the joints still name each."""
    config = _config(tmp_path, "{node_id: 1, joint: joint1, options: {serial_number: 1}}")
    with DrivesBench(config) as bench:
        network = canopen.Network(bench.bus("arm"))
        network.connect()
        _assign(network, 1)                                        # taken by joint1
        assert wait_until(lambda: [d.node_id for d in bench.sim.drives[:2]] == [1, 1])
        with pytest.raises(HilError) as refused:
            bench.sim.drive("arm", 1)
        said = str(refused.value)
        assert "node id 1 on bus 'arm' is the drive of joint1 and of joint2" in said
        assert "name the drive by its joint" in said
        bench.fault("joint2")
        assert bench.state("joint2").endswith("FAULT")
        assert not bench.state("joint1").endswith("FAULT")
        with pytest.raises(HilError, match="no drive has node id 255 on bus 'arm' now"):
            bench.sim.raise_fault("arm", 255)
        network.disconnect()
