"""A drive profile's reply to its cycle's command: frames it hands over (``take_replies``),
sent with the other replies of its bus in one go, or sent by the profile itself."""

from __future__ import annotations

from contextlib import nullcontext

import can
import pytest

from conftest import TEST_MOTOR_DRIVE, CanopenBench
from test_cia402_files import drive_config

from hil.can.frame import Frame
from hil.drives import DriveCore, DriveParameters
from hil.drives.profile import DriveProfile
from hil.protocols.cia402 import Cia402


class Silent(DriveProfile):
    protocol = Cia402

    def subscriptions(self):
        return []


def test_a_profile_that_defines_neither_way_of_replying_is_refused_when_made():
    with pytest.raises(TypeError, match="neither take_replies nor send_replies"):
        Silent(drive_config(1), DriveCore(DriveParameters(**TEST_MOTOR_DRIVE)), nullcontext())


@pytest.fixture
def lock_step_bench():
    bench = CanopenBench(lock_step=True)
    yield bench
    bench.close()


def test_lock_step_replies_leave_in_config_order_with_a_self_sending_profile_in_its_place(
        lock_step_bench):
    bench = lock_step_bench
    third = bench.sim.drive("arm", 3)
    third.take_replies = lambda: None                      # as a profile of an older hil
    third.send_replies = lambda: (third.tpdos.take(), third.send(Frame(0x7AA, b"\x03")))
    reader = can.BufferedReader()
    bench.network.notifier.add_listener(reader)
    # NMT start: handled in this thread (the drives' bus delivers in the sender's)
    bench.master_bus.send(can.Message(arbitration_id=0x000, data=[0x01, 0x00],
                                      is_extended_id=False))
    bench.master_bus.send(can.Message(arbitration_id=0x080, data=b"", is_extended_id=False))
    expected = [0x181, 0x281, 0x182, 0x282, 0x7AA, 0x184, 0x284, 0x185, 0x285, 0x186, 0x286]
    heard = []
    while len(heard) < len(expected) and (msg := reader.get_message(5.0)) is not None:
        if msg.arbitration_id in expected:      # not the heartbeats and boot-ups around
            heard.append(msg.arbitration_id)
    assert heard == expected
