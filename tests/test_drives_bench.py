"""The drives-only bench (hil.testing.DrivesBench) a user's master is tested against: what
it says of the drives, how time runs, and its errors; its pytest examples are in
docs/testing.md (run by tests/test_docs.py)."""

from __future__ import annotations

import time

import can
import pytest

from hil.cli import main
from hil.errors import HilError
from hil.protocols.mit import ENTER_MOTOR_MODE, MitCommand, pack_command
from hil.testing import DrivesBench


@pytest.fixture
def ur3_bench():
    bench = DrivesBench("ur3")
    yield bench
    bench.close()


def test_a_joints_drive_is_named_with_its_units(ur3_bench):
    joint = ur3_bench.drive("joint2")
    assert (joint.bus, joint.node_id, joint.protocol) == ("arm", 2, "cia402")
    assert joint.reduction == pytest.approx(120) and joint.counts_per_rev == 131072
    assert ur3_bench.eds().is_file()


def test_real_time_counts_the_cycles_of_any_master_by_its_syncs(ur3_bench):
    """Issue 46: hil sim's status printed `cycles 0` while the user's master sent SYNCs."""
    bus = ur3_bench.bus("arm")
    for _ in range(20):
        bus.send(can.Message(arbitration_id=0x080, is_extended_id=False, data=b""))
        time.sleep(0.005)
    deadline = time.monotonic() + 5
    while ur3_bench.sim.cycles < 20 and time.monotonic() < deadline:
        time.sleep(0.05)
    assert ur3_bench.sim.cycles == 20


def test_lock_step_advances_by_the_tests_step_only_where_no_master_runs():
    with DrivesBench("ur3", lock_step=True) as bench:
        before = bench.sim.now()
        time.sleep(0.2)
        assert bench.sim.now() == before                     # nothing steps it by itself
        bench.step(50)
        assert bench.sim.now() == pytest.approx(before + 50 * 0.002)


@pytest.fixture(scope="module")
def ur3_mit(tmp_path_factory):
    """The ur3 on MIT-protocol motors, one bus (as `hil init ur3 --protocol mit` writes it)."""
    config = tmp_path_factory.mktemp("mit") / "ur3_mit.yaml"
    assert main(["init", "ur3", "--protocol", "mit", "-o", str(config)]) == 0
    return config


def mit_answers(config, commanded: int, cycles: int) -> tuple[list[list], int]:
    """A lock-step run of an MIT client that commands the first ``commanded`` motors (each
    to hold where it is, with the config's gains) and steps, ``cycles`` times: the answers
    in its bus after each step (id, data), and the plant's cycles."""
    with DrivesBench(config, lock_step=True) as bench:
        bus = bench.bus()
        drives = [bench.drive(joint) for joint in bench.joints()][:commanded]
        for drive in drives:
            bus.send(can.Message(arbitration_id=drive.node_id, is_extended_id=False,
                                 data=ENTER_MOTOR_MODE))
        bench.step()
        while bus.recv(0) is not None:
            pass
        holds = [pack_command(MitCommand(0.0, 0.0, drive.config.options.kp,
                                         drive.config.options.kd, 0.0),
                              drive.config.options.ranges) for drive in drives]
        answers = []
        for _ in range(cycles):
            for drive, hold in zip(drives, holds):
                bus.send(can.Message(arbitration_id=drive.node_id, is_extended_id=False,
                                     data=hold))
            bench.step()
            answers.append([(answer.arbitration_id, bytes(answer.data))
                            for answer in iter(lambda: bus.recv(0), None)])
        return answers, bench.sim.cycles


@pytest.mark.parametrize("commanded", [2, 6])
def test_lock_step_answers_every_command_before_the_step_returns(ur3_mit, commanded):
    """Issue 64: six MIT commands and step(), 300 times, brought about 180 answers a motor
    (a Notifier thread took the frames after the step had closed their cycle). docs/testing.md:
    every frame sent before step() is in its cycle, answered once (the MIT reply to each
    command, hil.protocols.mit), the answers in the master's bus when step() returns; the
    same run twice is the same run. A master that commands every motor closes each cycle
    itself: one period a step either way."""
    answers, cycles = mit_answers(ur3_mit, commanded, 200)
    assert [len(cycle) for cycle in answers] == [commanded] * 200
    assert cycles == 201
    assert (answers, cycles) == mit_answers(ur3_mit, commanded, 200)


@pytest.mark.parametrize("call, said", [
    (lambda bench: bench.step(), r"step\(\) advances a lock-step bench"),
    (lambda bench: bench.drive("elbow"), "no drive moves joint 'elbow'"),
    (lambda bench: bench.fault("joint2", "melt"), "no fault kind 'melt'"),
    (lambda bench: bench.bus(), "has buses arm, wrist"),
    (lambda bench: bench.joint("elbow"), "no joint 'elbow'"),
])
def test_a_wrong_call_says_what_to_do(ur3_bench, call, said):
    with pytest.raises(HilError, match=said):
        call(ur3_bench)


def test_an_injected_fault_is_the_drives_state(ur3_bench):
    ur3_bench.fault("joint3")
    assert ur3_bench.state("joint3").endswith("FAULT")         # CiA 402 state, NMT first


def test_vcan_must_name_every_bus():
    with pytest.raises(HilError, match="give every bus of the config a SocketCAN interface"):
        DrivesBench("ur3", vcan={"arm": "vcan0"})


@pytest.mark.socketcan
def test_a_master_on_socketcan_reaches_the_drives_of_a_vcan_bench():
    """A master that opens SocketCAN itself (canopen over socketcan vcan0), inside UML."""
    import canopen

    from conftest import socketcan_missing

    missing = socketcan_missing("vcan0", "vcan1")
    if missing:
        pytest.skip(missing)
    with DrivesBench("ur3", lock_step=True, vcan={"arm": "vcan0", "wrist": "vcan1"}) as bench:
        network = canopen.Network()
        network.connect(interface="socketcan", channel="vcan0")
        try:
            node = network.add_node(2, str(bench.eds()))
            assert node.sdo[0x1000].raw == 0x00020192           # CiA 402 servo drive
        finally:
            network.disconnect()


def test_a_frozen_bench_stands_still_and_its_drives_answer_from_there(ur3_bench):
    ur3_bench.freeze()
    frozen = ur3_bench.sim.now()
    bus = ur3_bench.bus("arm")
    bus.send(can.Message(arbitration_id=0x000, data=[0x01, 0x00], is_extended_id=False))
    bus.send(can.Message(arbitration_id=0x080, is_extended_id=False))     # SYNC: the TPDOs
    answers = iter(lambda: bus.recv(5), None)
    assert any(msg.arbitration_id == 0x181 for msg in answers)
    assert ur3_bench.sim.now() == frozen
