"""RTR-requested TPDOs and the SYNC counter (CiA 301 7.2.2.2, 7.2.5; 0x1019; the TPDO's
SYNC start value, sub-index 6), as python canopen's master and raw frames see them."""

from __future__ import annotations

import time

import can
import pytest

from test_cia402_conformance import FrameTap, abort_code, pre_operational, wait_until

TPDO2 = 0x281


def _remote(bench, can_id: int) -> None:
    bench.master_bus.send(can.Message(arbitration_id=can_id, is_remote_frame=True, dlc=6,
                                      is_extended_id=False))


def _answers_to_rtr(bench, can_id: int, timeout: float = 1.0) -> list[can.Message]:
    """The data frames on ``can_id`` within ``timeout`` of a remote frame on it."""
    with FrameTap(bench) as tap:
        _remote(bench, can_id)
        wait_until(lambda: [m for m in tap.of(can_id) if not m.is_remote_frame], timeout)
        time.sleep(0.1)
    return [m for m in tap.of(can_id) if not m.is_remote_frame]


def _operational(bench):
    node = pre_operational(bench)
    node.sdo[0x1801][2].raw = 253                # TPDO2: RTR only, asynchronous
    node.nmt.state = "OPERATIONAL"
    return node


@pytest.mark.wire("RTR frames exist on a real bus")
def test_an_rtr_on_a_tpdo_that_allows_it_is_answered_with_the_tpdo(canopen_bench):
    node = _operational(canopen_bench)
    answers = _answers_to_rtr(canopen_bench, TPDO2)
    assert len(answers) == 1 and len(answers[0].data) == 6   # velocity, torque actual
    node.sdo[0x1801][1].raw = 0x40000000 | TPDO2   # bit 30: no RTR allowed
    node.nmt.state = "PRE-OPERATIONAL"
    node.nmt.state = "OPERATIONAL"
    assert _answers_to_rtr(canopen_bench, TPDO2) == []


@pytest.mark.wire("RTR frames exist on a real bus")
def test_an_rtr_outside_operational_is_not_answered(canopen_bench):
    node = _operational(canopen_bench)
    node.nmt.state = "PRE-OPERATIONAL"
    assert _answers_to_rtr(canopen_bench, TPDO2) == []


@pytest.mark.wire("a SYNC's counter byte on the wire")
def test_with_a_sync_counter_a_sync_must_carry_it_and_a_tpdo_starts_at_its_start_value(
        canopen_bench):
    node = pre_operational(canopen_bench)
    assert abort_code(lambda: node.sdo.download(0x1019, 0, b"\x01")) == 0x06090030
    node.sdo[0x1019].raw = 10                    # SYNCs count 1..10
    node.sdo[0x1800][1].raw = 0x80000181         # TPDO1 not valid while its start changes
    node.sdo[0x1800][2].raw = 2                  # every 2nd SYNC
    node.sdo[0x1800][6].raw = 3                  # from the SYNC whose counter is 3
    node.sdo[0x1800][1].raw = 0x181
    node.nmt.state = "OPERATIONAL"
    with FrameTap(canopen_bench) as tap:
        for counter in range(1, 9):
            canopen_bench.network.sync.transmit(counter)
            time.sleep(0.05)
        assert wait_until(lambda: len(tap.of(0x181)) >= 3)
        time.sleep(0.3)
    # TPDO1 at the SYNCs counting 4, 6, 8: every 2nd SYNC from (and counting) the 3rd. A
    # start value ignored would have sent it at 2, 4, 6, 8 (four times)
    assert len(tap.of(0x181)) == 3
    node.emcy.reset()
    canopen_bench.network.sync.transmit()        # no counter where one is due
    assert wait_until(lambda: any(e.code == 0x8240 for e in node.emcy.log))


def test_profile_torque_ramps_to_the_target_on_the_torque_slope_and_halts_to_zero(canopen_bench):
    """CiA 402 profile torque (mode 4): 0x6071 reached at 0x6087 (per mille of 0x6076 per
    second); statusword bit 10 once there; halt (bit 8) ramps the torque to 0."""
    node = pre_operational(canopen_bench)
    node.sdo[0x6060].raw = 4
    node.sdo[0x6087].raw = 1000                  # the rated torque in one second
    assert abort_code(lambda: node.sdo.download(0x6088, 0, b"\x01\x00")) == 0x06090030
    node.nmt.state = "OPERATIONAL"
    for word in (0x06, 0x07, 0x0F):
        node.sdo[0x6040].raw = word
    assert wait_until(lambda: node.sdo[0x6041].raw & 0x6F == 0x27)
    drive = canopen_bench.sim.drive("arm", 1)
    target, slope = drive.rated_torque * 0.1, drive.rated_torque    # per s
    node.sdo[0x6071].raw = 100                   # 10 % of the rated torque: 0.1 s away
    # the drive's lock held, nothing else steps the ramp: a step of 10 ms on the drive's
    # clock moves the torque by the slope's 10 ms, never further (no host clock judged)
    with canopen_bench.sim.lock:
        before = drive.machine.torque_demand
        drive.machine.ramp_torque(0.01)
        stepped = drive.machine.torque_demand - before
    assert stepped == pytest.approx(min(0.01 * slope, target - before))
    assert wait_until(lambda: node.sdo[0x6041].raw & 0x0400)
    assert drive.machine.torque_demand == target
    node.sdo[0x6040].raw = 0x010F                # halt
    assert wait_until(lambda: drive.machine.torque_demand == 0.0)
    assert node.sdo[0x6061].raw == 4
