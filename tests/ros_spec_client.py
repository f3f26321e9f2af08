"""A ROS 2 client on Zenoh written from rmw_zenoh's design document alone (docs/design.md:
key expressions, liveliness tokens, the 33-byte attachment) and rcl_action's names, to hold
hil's ROS face against. It imports nothing of hil's ROS adapter (hil.messaging.ros); CDR
comes from hil.messaging.cdr, a rosbags codec.

It finds every endpoint through the graph (a liveliness query), as an rmw_zenoh context
does, and takes key expressions, type names and hashes from the tokens.
"""

from __future__ import annotations

import itertools
import os
import struct
import time
from dataclasses import dataclass

import zenoh

ATTACHMENT = struct.Struct("<qqB16s")    # sequence number, source timestamp, GID length, GID


@dataclass(frozen=True)
class Token:
    """An entity as its liveliness token says (design.md, "Graph Cache")."""

    kind: str
    node: str
    namespace: str
    name: str = ""
    type_name: str = ""
    type_hash: str = ""
    qos: str = ""

    @classmethod
    def parse(cls, text: str) -> Token:
        parts = text.split("/")
        assert parts[0] == "@ros2_lv", text
        demangle = lambda chunk: chunk.replace("%", "/")   # noqa: E731
        if parts[5] == "NN":
            assert len(parts) == 9, text
            return cls("NN", parts[8], demangle(parts[7]))
        assert len(parts) == 13, text
        return cls(parts[5], parts[8], demangle(parts[7]), demangle(parts[9]),
                   demangle(parts[10]), demangle(parts[11]), parts[12])

    def key(self, domain: int) -> str:
        """``<domain>/<fully qualified name>/<type name>/<type hash>``."""
        return f"{domain}/{self.name.strip('/')}/{self.type_name}/{self.type_hash}"


class SpecClient:
    """A Zenoh client session with its own GID and sequence numbers."""

    def __init__(self, router: str, domain: int = 0):
        config = zenoh.Config()
        config.insert_json5("mode", '"client"')
        config.insert_json5("connect/endpoints", f'["{router}"]')
        config.insert_json5("scouting/multicast/enabled", "false")
        self.session = zenoh.open(config)
        self.domain = domain
        self.gid = os.urandom(16)
        self._sequence = itertools.count(1)

    def graph(self) -> list[Token]:
        replies = self.session.liveliness().get(f"@ros2_lv/{self.domain}/**", timeout=2.0)
        return [Token.parse(str(r.ok.key_expr)) for r in replies if r.ok is not None]

    def find(self, kind: str, name: str, timeout: float = 10.0) -> Token:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for token in self.graph():
                if token.kind == kind and token.name == name:
                    return token
            time.sleep(0.1)
        raise AssertionError(f"no {kind} {name} in the graph")

    def attachment(self) -> tuple[int, bytes]:
        sequence = next(self._sequence)
        return sequence, ATTACHMENT.pack(sequence, time.time_ns(), 16, self.gid)

    def call(self, service: Token, payload: bytes, timeout: float = 30.0) -> bytes:
        """One request; checks the reply echoes this request's sequence number and GID."""
        sequence, attachment = self.attachment()
        replies = list(self.session.get(
            service.key(self.domain), payload=payload, attachment=attachment,
            target=zenoh.QueryTarget.ALL_COMPLETE, consolidation=zenoh.ConsolidationMode.NONE,
            timeout=timeout))
        assert len(replies) == 1, f"{len(replies)} replies from {service.name}"
        assert replies[0].ok is not None, replies[0].err.payload.to_bytes()
        echoed, stamp, length, gid = ATTACHMENT.unpack(replies[0].ok.attachment.to_bytes())
        assert (echoed, length, gid) == (sequence, 16, self.gid), "reply attachment"
        assert abs(stamp - time.time_ns()) < 60e9, "reply source timestamp (ns since epoch)"
        return replies[0].ok.payload.to_bytes()

    def close(self) -> None:
        self.session.close()
