"""A zenoh bus' count of each sender's lost frames from its sequence numbers
(hil.can.link_statistics.SenderSequences): gaps are lost, a late message fills its own."""

from __future__ import annotations

from hil.can.link_statistics import GAPS_KEPT, SenderSequences


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
