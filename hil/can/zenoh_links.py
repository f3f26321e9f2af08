"""Who is on a Zenoh CAN channel, and whether this session is linked to each of them
directly: what :class:`hil.can.zenoh_bus.ZenohBus` waits for before its open returns.

On a CAN bus a frame sent once the bus is open reaches every node. Over Zenoh it reaches the
peers this session is linked to directly and no other: peers relay nothing
(:mod:`hil.zenoh_session`), and a new session links to the peers beyond its first one in
gossip's own time. A master that opened its bus and at once reset a node went unheard (an
outside CANopen master timed out waiting for the boot-up, 1 run in 3 on a loaded host), and
hil's own tests waited for a process' liveliness token, which a peer sees only over a direct
link, before their one-shot frames.

So each session declares, per channel it has buses on, two kinds of liveliness tokens:

* ``hil/can-members/<its zid>/<channel>``: it is on the channel. Another session sees it
  only over a direct link, so seeing it says that session's declarations (its frames'
  subscriber, declared first) have come: a frame sent from now on reaches it;
* ``hil/can-seen/<its zid>/<member zid>/<channel>``: it sees that member directly. These
  tell a newcomer of the members it is not linked to yet (the session it met first, the
  meeting point's, sees every one of them), and that a member sees the newcomer: that
  member has the newcomer's declarations, so a frame it sends from now on reaches it.

A newcomer's open waits until every member that it or any of its peers sees is one it sees
itself and that sees it (:meth:`ChannelLinks.wait_linked`): then a frame either sends
reaches the other. Nothing of it is on the frames' path.

What it cannot know is a member that no peer on the channel sees: where the session it met
first has no bus (no hil process but a bare Zenoh session holds the meeting point), the
members beyond it are linked in gossip's own time, as before.

Under ``--secure`` a role whose tokens the policy refuses (an operator's or an observer's
bus, :mod:`hil.zenoh_security`) is waited for by no one, and waits for the others without
waiting to be seen by them (it never is).
"""

from __future__ import annotations

import threading
import time

import zenoh

from hil.zenoh_session import ZenohSettings

#: where a session says it is on a channel (``<prefix>/<zid>/<channel>``)
MEMBERS = "hil/can-members"
#: where a session says which members of a channel it sees (``<prefix>/<zid>/<member>/<channel>``)
SEEN = "hil/can-seen"
#: the ``--secure`` roles whose liveliness tokens the other processes accept under these
#: keys (hil.zenoh_security's policy: "anything" for drives and controller; an observer's
#: token only at hil/*/viz, an operator's nowhere)
TOKEN_ROLES = ("drives", "controller")


def seen_by_others(settings: ZenohSettings) -> bool:
    """Whether other processes accept the tokens of a session of ``settings``."""
    return settings.identity is None or settings.identity.role in TOKEN_ROLES


class ChannelLinks:
    """One session's view of one channel's members: its own token, the members it sees
    directly, and those its peers see (each with who sees it)."""

    def __init__(self, session: zenoh.Session, channel: str, seen: bool = True):
        """``seen``: whether the others accept this session's tokens (:func:`seen_by_others`):
        else it does not wait to be seen."""
        self._session = session
        self._seen = seen
        self._channel = channel
        self._zid = str(session.zid())
        self._changed = threading.Condition()
        self._direct: set[str] = set()
        #: member zid -> the peers that report seeing it
        self._reported: dict[str, set[str]] = {}
        #: the members that report seeing this session
        self._seeing_me: set[str] = set()
        self._seen_tokens: dict[str, zenoh.LivelinessToken] = {}
        self._closed = False
        liveliness = session.liveliness()
        self._token = liveliness.declare_token(f"{MEMBERS}/{self._zid}/{channel}")
        # in Zenoh's receiving thread (indirect: a thread of its own, and the order against
        # wait_linked's query would be lost); history: the members there before this session
        self._subscribers = [
            liveliness.declare_subscriber(self._members_key(), zenoh.handlers.Callback(
                self._on_member, indirect=False), history=True),
            liveliness.declare_subscriber(self._seen_key(), zenoh.handlers.Callback(
                self._on_seen, indirect=False), history=True)]

    def _members_key(self) -> str:
        return f"{MEMBERS}/*/{self._channel}"

    def _seen_key(self) -> str:
        return f"{SEEN}/*/*/{self._channel}"

    def _on_member(self, sample: zenoh.Sample) -> None:
        member = str(sample.key_expr).split("/")[2]
        if member == self._zid:
            return
        with self._changed:
            if self._closed:
                return
            if sample.kind == zenoh.SampleKind.PUT:
                self._direct.add(member)
                if member not in self._seen_tokens:
                    self._seen_tokens[member] = self._session.liveliness().declare_token(
                        f"{SEEN}/{self._zid}/{member}/{self._channel}")
            else:
                self._direct.discard(member)
                token = self._seen_tokens.pop(member, None)
                if token is not None:
                    token.undeclare()
            self._changed.notify_all()

    def _on_seen(self, sample: zenoh.Sample) -> None:
        chunks = str(sample.key_expr).split("/")
        seer, member = chunks[2], chunks[3]
        if seer == self._zid:
            return
        with self._changed:
            seers = self._seeing_me if member == self._zid else self._reported.setdefault(
                member, set())
            if sample.kind == zenoh.SampleKind.PUT:
                seers.add(seer)
            else:
                seers.discard(seer)
                if not seers and member in self._reported:
                    del self._reported[member]
            self._changed.notify_all()

    def unlinked(self) -> dict[str, set[str]]:
        """The members not linked both ways with this session yet, each with the peers that
        see it (empty where only this session sees it, and it does not see this one yet)."""
        with self._changed:
            return {member: set(self._reported.get(member, ()))
                    for member in self._direct | set(self._reported)
                    if member not in self._direct
                    or (self._seen and member not in self._seeing_me)}

    def wait_linked(self, timeout: float) -> dict[str, set[str]]:
        """Wait until this session and every member it or its peers see are linked both
        ways (each sees the other), at most ``timeout`` s; the members still unlinked then
        (empty: linked to all).

        The members its peers knew before this session came arrive as the subscribers'
        history; a query of the same tokens, answered by each peer after that history (one
        link keeps its order), says when all of it has come."""
        deadline = time.monotonic() + timeout
        liveliness = self._session.liveliness()
        for key in (self._members_key(), self._seen_key()):
            for _ in liveliness.get(key, timeout=max(timeout, 0.001)):
                pass
        with self._changed:
            self._changed.wait_for(lambda: not self.unlinked(),
                                   max(0.0, deadline - time.monotonic()))
        return self.unlinked()

    def close(self) -> None:
        """Leave the channel: its tokens and subscribers undeclared."""
        for subscriber in self._subscribers:
            subscriber.undeclare()
        with self._changed:
            self._closed = True
            tokens, self._seen_tokens = list(self._seen_tokens.values()), {}
        for token in tokens + [self._token]:
            token.undeclare()


def not_linked(channel_info: str, unlinked: dict[str, set[str]], timeout: float) -> str:
    """Why a bus' open failed: the members it is not linked to, and what to do."""
    peers = "; ".join(f"{member} (seen by {', '.join(sorted(seers))})" if seers else
                      f"{member} (linked, not yet seeing this bus' session)"
                      for member, seers in sorted(unlinked.items()))
    return (f"{channel_info}: not linked to every peer on the channel after {timeout:g} s: "
            f"{peers}. Zenoh peers relay nothing, so a frame sent now would not reach them: "
            "can this host reach their listen endpoints (--listen, a firewall)? "
            "link_timeout=SECONDS waits longer")
