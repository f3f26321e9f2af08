"""Receipts of a CAN log over Zenoh: which frame of each sender a monitor (a bus opened with
``timestamps="sent"``, as ``hil viz`` logs) has heard, asked for by a lossless bus as it
shuts down, so that a lock-step run's log is whole to its last frame; and, asked by a
process that is to be logged from its first frame, whether a monitor has joined yet.

A Zenoh session's queue for a link holds what it has not sent yet: about 400 cycles of a
ur3's frames for a visualiser that fell behind, which closing the session drops (the log of
a lock-step run then lacked the controller's last cycles, and its replay failed). So a
lossless bus waits before it closes until every monitor that has heard from it has heard its
last frame, or LINGER passes (then it says how many monitors were behind).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable

import zenoh

from hil.can.link_statistics import SEQUENCE_HALF, SEQUENCE_MASK
from hil.zenoh_security import RECEIPTS_KEY

#: how long a lossless bus waits for the monitors at its shutdown (s)
LINGER = 10.0
#: how long a process asked to wait for a monitor at its start waits for one (s)
AWAIT_MONITOR = 30.0
#: how often it asks (s)
_POLL = 0.02


def receipts_payload(heard: Iterable[tuple[str, dict[int, int]]]) -> bytes:
    """Lines "<channel> <sender> <its last sequence number heard>" of monitors' buses, each
    given as (channel, {sender: sequence})."""
    return "".join(f"{channel} {sender} {sequence}\n" for channel, senders in heard
                   for sender, sequence in senders.items()).encode()


def declare_receipts(session: zenoh.Session,
                     heard: Callable[[], Iterable[tuple[str, dict[int, int]]]]):
    """The session's queryable that answers with ``heard()``'s receipts."""
    def answer(query: zenoh.Query) -> None:
        query.reply(query.key_expr, receipts_payload(heard()))

    return session.declare_queryable(f"{RECEIPTS_KEY}/{session.zid()}", answer)


def monitors_behind(session: zenoh.Session, channel: str, sender: int, last: int) -> int:
    """How many monitors that have heard ``sender`` on ``channel`` have not heard its frame
    numbered ``last`` (masked to 32 bits)."""
    behind = 0
    for reply in session.get(f"{RECEIPTS_KEY}/*", timeout=1.0):
        if reply.ok is None:
            continue
        for line in reply.ok.payload.to_bytes().decode(errors="replace").splitlines():
            name, _, rest = line.rpartition(" ")
            name, _, heard_from = name.rpartition(" ")
            if name == channel and heard_from == str(sender) and rest.isdigit():
                gap = (last - int(rest)) & SEQUENCE_MASK
                behind += 0 < gap < SEQUENCE_HALF
    return behind


def wait_for_monitor(session: zenoh.Session, timeout: float = AWAIT_MONITOR) -> bool:
    """Wait until a monitor answers this session's receipts query, at most ``timeout`` s;
    whether one did.

    A monitor's session declares its subscriber of every CAN key before its receipts
    queryable (:class:`hil.can.zenoh_channels.Channels`), and a session's declarations
    reach a peer in the order made. So once a query of this session reaches the queryable,
    this session knows the subscriber too, and every frame it puts from then on reaches the
    monitor. A frame put before that went nowhere: a lock-step log lacked its drives'
    boot-ups, put as the visualiser's subscription was still on its way, and did not replay."""
    deadline = time.monotonic() + timeout
    while True:
        if any(reply.ok is not None
               for reply in session.get(f"{RECEIPTS_KEY}/*", timeout=min(1.0, timeout))):
            return True
        if time.monotonic() >= deadline:
            return False
        time.sleep(_POLL)


def wait_until_heard(session: zenoh.Session, channel: str, sender: int, last: int,
                     linger: float = LINGER) -> int:
    """Wait until no monitor is behind ``sender``'s frame ``last`` on ``channel``, at most
    ``linger`` s; how many still were."""
    deadline = time.monotonic() + linger
    while True:
        behind = monitors_behind(session, channel, sender, last & SEQUENCE_MASK)
        if not behind or time.monotonic() >= deadline:
            return behind
        time.sleep(_POLL)
