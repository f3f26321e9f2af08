"""Virtual CiA 402 drives driven by python canopen's own master (RemoteNode/BaseNode402).

Each test runs over python-can's in-process ``virtual`` bus here and over real
SocketCAN vcan0 inside User-Mode Linux (the ``socketcan`` marked variant).
"""

from __future__ import annotations

import math
import random
import struct
import threading
import time

import can
import canopen
import pytest

from conftest import EDS, MASTER_PATIENCE, patient

from hil.protocols.cia402 import EMCY_FOLLOWING_ERROR
from hil.protocols.cia402.state import SUPPORTED_MODES

CYCLE = 0.01          # the fixture config's 100 Hz SYNC
COUNTS = 131072       # encoder counts per motor revolution (fixture default)
REDUCTION = 120.0     # joint1 of the ur3


def enable_csp(bench, node_id: int = 1):
    """The canopen master's way: NMT, PDO maps read over SDO, SYNC, 402 to OPERATION ENABLED."""
    node = bench.node402(node_id)
    node.nmt.state = "PRE-OPERATIONAL"
    node.setup_402_state_machine(read_pdos=True)
    node.nmt.state = "OPERATIONAL"
    bench.start_sync(CYCLE)
    node.rpdo[1].start(CYCLE)
    node.op_mode = "CYCLIC SYNCHRONOUS POSITION"
    node.rpdo[1]["Target position"].raw = node.tpdo[1]["Position actual value"].raw
    node.state = "OPERATION ENABLED"
    return node


def emcy_logged_after(node, code: int, earlier: int | None = None,
                      timeout: float = MASTER_PATIENCE) -> bool:
    """Whether EMCY ``code`` arrives (or arrived) after EMCY ``earlier`` (or at all)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        codes = [e.code for e in node.emcy.log]
        if earlier is None and code in codes:
            return True
        if earlier in codes and code in codes[codes.index(earlier) + 1:]:
            return True
        time.sleep(0.01)
    return False


def joint_from_counts(counts: int) -> float:
    return counts / COUNTS * 2 * math.pi / REDUCTION


@pytest.mark.wire("canopen's master moves the joint over SocketCAN")
def test_canopen_master_moves_the_mujoco_joint_in_csp(canopen_bench):
    node = enable_csp(canopen_bench)
    assert node.state == "OPERATION ENABLED"
    assert node.op_mode == "CYCLIC SYNCHRONOUS POSITION"
    start = node.tpdo[1]["Position actual value"].raw
    goal = start + round(0.2 * REDUCTION / (2 * math.pi) * COUNTS)
    for i in range(1, 51):                       # ramp 0.2 rad over 0.5 s
        node.rpdo[1]["Target position"].raw = start + (goal - start) * i // 50
        node.tpdo[1].wait_for_reception(1)
    deadline = time.monotonic() + 3
    while abs(node.tpdo[1]["Position actual value"].raw - goal) > 50 and time.monotonic() < deadline:
        node.tpdo[1].wait_for_reception(1)
    actual_counts = node.tpdo[1]["Position actual value"].raw
    assert abs(actual_counts - goal) <= 50       # the arm got there
    # freeze the physics, then one SYNC: the TPDO reports the frozen plant
    canopen_bench.stop_sync()
    canopen_bench.drives.freeze()
    time.sleep(0.3)                              # let late replies to earlier SYNCs drain
    # listening before the SYNC leaves: on vcan the answer can beat a wait_for_reception
    answered = threading.Event()
    node.tpdo[1].add_callback(lambda pdo: answered.set())
    canopen_bench.network.sync.transmit()
    assert answered.wait(1), "no TPDO1 answered the SYNC"
    actual_counts = node.tpdo[1]["Position actual value"].raw
    joint = canopen_bench.sim.plant.joint_positions()[0]
    # TPDO position converted through the transmission = MuJoCo joint within one count
    assert abs(joint_from_counts(actual_counts) - joint) <= 2 * math.pi / COUNTS / REDUCTION
    assert joint == pytest.approx(0.2, abs=1e-3)


def test_statusword_and_mode_over_sdo_match_the_pdo(canopen_bench):
    node = enable_csp(canopen_bench)
    assert node.sdo[0x6041].raw & 0x6F == 0x27
    assert node.sdo[0x6061].raw == 8
    assert node.sdo[0x6502].raw == SUPPORTED_MODES == 0x3ED  # PP, PV, PT, HM, IP, CSP, CSV, CST
    assert node.sdo[0x608F][1].raw == COUNTS
    with pytest.raises(canopen.SdoAbortedError) as refused:     # velocity mode (vl)
        node.sdo[0x6060].raw = 2
    assert refused.value.code == 0x06090030


@pytest.mark.wire("a silent master on the wire stops the axis")
def test_silent_controller_trips_the_watchdog_into_quick_stop_with_emcy(canopen_bench):
    node = enable_csp(canopen_bench)
    timeout = canopen_bench.config.drives[0].watchdog_timeout
    node.rpdo[1].stop()                          # setpoints stop; SYNC goes on
    silent_since = time.monotonic()
    emcy = node.emcy.wait(0x8250, timeout=timeout + 2)
    waited = time.monotonic() - silent_since
    assert emcy is not None, "no RPDO-timeout EMCY"
    assert timeout * 0.9 <= waited < timeout + 1.0
    node.tpdo[1].wait_for_reception(1)
    assert node.state == "QUICK STOP ACTIVE"


@pytest.mark.wire("EMCY and a fault reset over the wire")
def test_following_error_faults_with_emcy_and_fault_reset_recovers(canopen_bench):
    node = enable_csp(canopen_bench)
    start = node.tpdo[1]["Position actual value"].raw
    jump = round(1.0 * REDUCTION / (2 * math.pi) * COUNTS)   # 1 rad in one 10 ms cycle
    node.rpdo[1]["Target position"].raw = start + jump
    assert emcy_logged_after(node, EMCY_FOLLOWING_ERROR, timeout=2)
    assert next(e for e in node.emcy.log if e.code == EMCY_FOLLOWING_ERROR).register & 0x01
    node.tpdo[1].wait_for_reception(1)
    node.tpdo[1].wait_for_reception(1)
    assert node.state == "FAULT"
    assert node.sdo[0x603F].raw == 0x8611
    here = node.tpdo[1]["Position actual value"].raw
    node.rpdo[1]["Target position"].raw = here
    node.reset_from_fault()                      # rising edge of bit 7, then back to enabled
    assert node.state == "OPERATION ENABLED"
    assert emcy_logged_after(node, 0x0000, EMCY_FOLLOWING_ERROR)   # "error reset" EMCY


@pytest.mark.wire("any frame the kernel delivers")
def test_garbage_frames_never_crash_the_drive(canopen_bench):
    node = enable_csp(canopen_bench)
    send = canopen_bench.master_bus.send
    send(can.Message(arbitration_id=0x201, data=b"\x0f\x00\x01", is_extended_id=False))
    assert emcy_logged_after(node, 0x8210)                    # PDO length error
    send(can.Message(arbitration_id=0x080, data=b"\x01\x02\x03", is_extended_id=False))
    assert emcy_logged_after(node, 0x8240)                    # SYNC length error
    rng = random.Random(402)
    for _ in range(3000):
        arbitration_id = rng.choice([0x000, 0x080, 0x201, 0x301, 0x401, 0x601, 0x77F,
                                     rng.randrange(0x800)])
        data = bytes(rng.randrange(256) for _ in range(rng.randrange(9)))
        send(can.Message(arbitration_id=arbitration_id, data=data, is_extended_id=False))
    send(can.Message(arbitration_id=0x1FFFFFFF, data=b"\xff" * 8, is_extended_id=True))
    time.sleep(0.3)
    # still a working CANopen node: reset it, it boots, and a fresh master (whose SDO
    # client saw none of the garbage's replies) reads its device type
    time.sleep(0.5)
    boot = can.BufferedReader()
    canopen_bench.network.notifier.add_listener(boot)
    try:
        node.nmt.send_command(0x81)
        deadline = time.monotonic() + 2 * MASTER_PATIENCE    # the garbage is drained first
        booted = False
        while time.monotonic() < deadline and not booted:
            msg = boot.get_message(0.1)
            booted = msg is not None and msg.arbitration_id == 0x701 and bytes(msg.data) == b"\0"
    finally:
        canopen_bench.network.notifier.remove_listener(boot)
    assert booted, "no boot-up message after the garbage"
    fresh_bus = can.Bus(interface=canopen_bench.interface, channel=canopen_bench.channel)
    fresh = canopen.Network(fresh_bus)
    fresh.notifier = can.Notifier(fresh_bus, fresh.listeners, 0.1)
    try:
        remote = patient(canopen.RemoteNode(1, str(EDS)))
        fresh.add_node(remote)
        remote.sdo.MAX_RETRIES = 10              # a slow machine may still be draining
        assert remote.sdo[0x1000].raw == 0x00020192
    finally:
        fresh.notifier.stop(1)
        fresh_bus.shutdown()


def _heartbeat_state(node, expected: str, heartbeats: int = 10) -> str:
    """The state the node's heartbeats report, once one reports ``expected`` (or after
    ``heartbeats`` of them): a heartbeat already on its way when the NMT command went out
    still says the state before it."""
    for _ in range(heartbeats):
        state = node.nmt.wait_for_heartbeat(timeout=1)
        if state == expected:
            break
    return state


def test_heartbeat_reports_the_nmt_state(canopen_bench):
    node = canopen_bench.node402(1)
    node.nmt.state = "OPERATIONAL"
    assert _heartbeat_state(node, "OPERATIONAL") == "OPERATIONAL"
    node.nmt.state = "STOPPED"
    assert _heartbeat_state(node, "STOPPED") == "STOPPED"


def test_pdo_mapping_is_the_documented_default(canopen_bench):
    node = canopen_bench.node402(3)
    node.nmt.state = "PRE-OPERATIONAL"
    node.tpdo.read()
    node.rpdo.read()
    assert [v.index for v in node.rpdo[1]] == [0x6040, 0x607A]
    assert [v.index for v in node.rpdo[2]] == [0x6040, 0x60FF]
    assert [v.index for v in node.rpdo[3]] == [0x6040, 0x6071]
    assert [v.index for v in node.tpdo[1]] == [0x6041, 0x6064]
    assert [v.index for v in node.tpdo[2]] == [0x606C, 0x6077]
    assert (node.rpdo[1].cob_id, node.tpdo[1].cob_id, node.tpdo[2].cob_id) == (0x203, 0x183, 0x283)
    assert node.tpdo[1].trans_type == 1


def _raw(bench, arbitration_id, data):
    bench.master_bus.send(can.Message(arbitration_id=arbitration_id, data=data,
                                      is_extended_id=False))


def _torque_seen(bench, node, frames, expected: int, seconds: float = 2.0) -> int:
    """Send ``frames`` each cycle until TPDO2's torque is ``expected`` or time is up; the
    last torque seen."""
    deadline, measured = time.monotonic() + seconds, None
    while time.monotonic() < deadline and measured != expected:
        for arbitration_id, data in frames:
            _raw(bench, arbitration_id, data)
        node.tpdo[2].wait_for_reception(1)
        measured = node.tpdo[2]["Torque actual value"].raw
    return measured


def test_csv_and_cst_modes_move_the_joint(canopen_bench):
    node = enable_csp(canopen_bench)
    node.op_mode = "CYCLIC SYNCHRONOUS VELOCITY"
    node.rpdo[1].stop()
    start = node.tpdo[1]["Position actual value"].raw
    velocity = round(0.2 * REDUCTION / (2 * math.pi) * COUNTS)      # 0.2 rad/s at the joint
    deadline = time.monotonic() + 5
    measured = 0
    while time.monotonic() < deadline and abs(measured - velocity) > 0.05 * velocity:
        _raw(canopen_bench, 0x301, struct.pack("<Hi", 0x0F, velocity))
        node.tpdo[2].wait_for_reception(1)
        measured = node.tpdo[2]["Velocity actual value"].raw
    assert abs(measured - velocity) <= 0.05 * velocity
    node.tpdo[1].wait_for_reception(1)
    assert node.tpdo[1]["Position actual value"].raw > start
    node.op_mode = "CYCLIC SYNCHRONOUS TORQUE"
    torque = 100                                                      # per mille of rated
    assert _torque_seen(canopen_bench, node, [(0x401, struct.pack("<Hh", 0x0F, torque))], torque,
                        seconds=5) == torque


def test_rpdo4_carries_the_offsets_once_a_master_makes_it_valid(canopen_bench):
    node = enable_csp(canopen_bench)
    node.rpdo.read()
    assert [v.index for v in node.rpdo[4]] == [0x60B1, 0x60B2] and not node.rpdo[4].enabled
    node.op_mode = "CYCLIC SYNCHRONOUS TORQUE"
    node.rpdo[1].stop()
    target = (0x401, struct.pack("<Hh", 0x0F, 100))           # 10 % of rated torque
    offset = (0x501, struct.pack("<ih", 0, -30))               # torque offset -3 %
    assert _torque_seen(canopen_bench, node, [target], 100) == 100
    # not valid: a frame of its id is nobody's PDO (a mixed bus' other protocols use it)
    assert _torque_seen(canopen_bench, node, [target, offset], 70, seconds=0.5) == 100
    node.sdo[0x1403][1].raw = 0x501
    # CST: the torque offset adds to the target torque, exactly
    assert _torque_seen(canopen_bench, node, [target, offset], 70) == 70
    node.sdo[0x60B2].raw = 0                                    # by SDO as well
    assert _torque_seen(canopen_bench, node, [target], 100) == 100


@pytest.mark.parametrize("mapped", [(0x6061, 0x6064), (0x6060, 0x6064)],
                         ids=["live objects", "with a stored object"])
def test_a_tpdo_remapped_by_sdo_carries_its_new_objects_after_nmt_start(canopen_bench, mapped):
    node = canopen_bench.node402(1)
    node.nmt.state = "PRE-OPERATIONAL"
    node.tpdo.read()
    node.rpdo.read()
    tpdo = node.tpdo[2]
    tpdo.clear()
    for index in mapped:
        tpdo.add_variable(index)
    tpdo.trans_type = 1
    tpdo.enabled = True
    tpdo.save()
    node.sdo[0x6060].raw = 8                         # cyclic synchronous position
    node.nmt.state = "OPERATIONAL"                   # the new mapping takes effect
    time.sleep(0.1)
    answered = threading.Event()
    tpdo.add_callback(lambda pdo: answered.set())
    before = node.sdo[0x6064].raw
    canopen_bench.network.sync.transmit()
    assert answered.wait(1), "no TPDO2 answered the SYNC"
    assert len(tpdo.data) == sum(variable.length for variable in tpdo.map) // 8
    after = node.sdo[0x6064].raw
    values = {variable.index: variable.raw for variable in tpdo.map}
    # the position at the SYNC: a braked arm may still settle by a few counts meanwhile
    assert min(before, after) - 1 <= values[0x6064] <= max(before, after) + 1
    if 0x6061 in values:
        assert values[0x6061] == 8
    else:
        assert values[0x6060] == 8


def test_the_heartbeat_keeps_its_phase_and_sends_one_beat_after_a_stall():
    from hil.protocols.cia402.node import ClockedNmtSlave
    # the drive's clock, injected: a value of the host's (its uptime) would make the sums
    # below round differently from host to host
    start = 1000.0
    nmt = ClockedNmtSlave(1, local_node=None, clock=lambda: start)
    nmt._state = 0x7F                               # PRE-OPERATIONAL
    nmt.start_heartbeat(50)
    assert nmt._due == start
    beats = [now for now in (start + 0.001 * ms for ms in range(0, 400))
             if nmt.heartbeat_due(now) is not None]
    assert beats == pytest.approx([start + 0.05 * k for k in range(8)], abs=1e-6)
    # a stall of three periods: one beat when the clock runs again, the next a period on
    later = start + 0.55
    assert nmt.heartbeat_due(later) == bytes([0x7F])
    assert nmt.heartbeat_due(later + 0.049) is None
    assert nmt.heartbeat_due(later + 0.05) == bytes([0x7F])


def test_the_nmt_operational_flag_follows_every_state_change():
    from hil.protocols.cia402.node import ClockedNmtSlave
    nmt = ClockedNmtSlave(1, local_node=None)
    assert not nmt.operational
    for command, operational in ((0x01, True), (0x80, False), (0x01, True), (0x02, False)):
        nmt.on_command(0, bytes([command, 1]), 0.0)       # start, pre-op, start, stop
        assert nmt.operational is operational
        assert (nmt.state == "OPERATIONAL") is operational
