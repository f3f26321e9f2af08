"""A zenoh bus' count of each sender's lost frames from its sequence numbers
(hil.can.link_statistics.SenderSequences): gaps are lost, a late message fills its own; and
its account of the link's round trip (hil.can.link_account.LinkAccount)."""

from __future__ import annotations

import pytest

from hil.can.frame import Frame
from hil.can.link_account import LinkAccount
from hil.can.link_statistics import GAPS_KEPT, SenderSequences
from hil.can.zenoh_wire import NO_ECHO, Echo, Message, decode_frames, encode_frames


def lost_after(messages: list[tuple[int, int]], sender: int = 7) -> tuple[int, int]:
    """(frames lost, the last number heard) after messages of (first number, frames)."""
    sequences = SenderSequences()
    lost = sum(sequences.arrived(sender, first, frames) for first, frames in messages)
    return lost, sequences.last[sender]


def test_messages_in_order_lose_nothing():
    assert lost_after([(1, 4), (5, 4), (9, 1)]) == (0, 9)


def test_a_gap_is_lost_until_its_message_comes_late():
    assert lost_after([(1, 4), (9, 4)]) == (4, 12)
    assert lost_after([(1, 4), (9, 4), (5, 4)]) == (0, 12)


def test_a_late_message_inside_a_gap_leaves_the_rest_of_it_lost():
    assert lost_after([(1, 1), (10, 1), (5, 2)]) == (6, 10)       # 2-9 missing, 5 and 6 came
    assert lost_after([(1, 1), (10, 1), (5, 2), (2, 3), (7, 3)]) == (0, 10)


def test_a_repeated_message_takes_nothing_off():
    assert lost_after([(1, 4), (9, 4), (5, 4), (5, 4), (1, 4)]) == (0, 12)


def test_a_message_over_a_gap_and_frames_that_came_takes_nothing_off():
    assert lost_after([(1, 1), (5, 1), (3, 4)]) == (3, 5)


def test_numbers_wrap_at_32_bits():
    assert lost_after([(0xFFFFFFFE, 1), (2, 1)]) == (3, 2)       # FFFFFFFF, 0, 1 missing
    assert lost_after([(0xFFFFFFFE, 1), (2, 1), (0xFFFFFFFF, 3)]) == (0, 2)


def test_only_the_most_recent_gaps_are_kept():
    messages = [(1 + 2 * k, 1) for k in range(GAPS_KEPT + 5)]      # every other number lost
    late = [(2 + 2 * k, 1) for k in range(GAPS_KEPT + 4)]
    lost, _ = lost_after(messages + late)
    assert lost == 4                                               # the oldest 4 forgotten


def test_senders_are_counted_apart_and_forgotten_oldest_first():
    sequences = SenderSequences()
    assert sequences.arrived(1, 10, 1) == 0 and sequences.arrived(2, 10, 1) == 0
    assert sequences.arrived(1, 12, 1) == 1
    assert sequences.forget_oldest() == 1
    assert sequences.arrived(1, 20, 1) == 0                       # counted afresh
    assert sequences.arrived(2, 11, 1) == 0


def test_a_message_heard_after_the_send_read_its_clock_is_echoed_as_held_0_s():
    """The receiving thread may note a message after the sending thread read ``now``: the
    echo was held 0 s, not a negative time that the receiver refuses as malformed (and with
    it the message's frames: seen from `hil viz` beside a loaded host, 2026-12-06)."""
    account = LinkAccount(sender=1, where="test")
    now = 1000.0
    account.arrived(Message("test", 7, 41, 0.0, NO_ECHO, [Frame(0x42)]),
                    0.0, now + 5e-5)                  # heard 50 us after the send's clock read
    echo = account.sent(1, 1, now)
    (message,) = decode_frames(encode_frames("test", 1, 1, 0.0, [Frame(0x42, b"ok")], echo))
    assert message.echo == Echo(7, 41, 0.0)


def test_a_slow_link_is_one_stall_per_stretch_not_one_per_message():
    """Messages 2 ms apart, each answered 40 ms later: once four in a row were slow, one
    stall covers a round trip; the messages put inside it add none."""
    account = LinkAccount(sender=1, where="test")
    start = 1000.0
    stalls = []
    for k in range(30):
        account.sent(k + 1, 1, start + k * 0.002)
        arrived = start + k * 0.002 + 0.040
        answer = Message("test", 2, k + 1, arrived, Echo(1, k + 1, 0.0), [Frame(0x181)])
        stalls += account.arrived(answer, arrived, arrived)
    assert [round(s.at - start, 3) for s in stalls] == [0.006, 0.046]
    assert all(s.process == "link" and s.length == pytest.approx(0.040) for s in stalls)
    assert account.counters.round_trips == 30
    assert account.counters.round_trip_floor == pytest.approx(0.040)
