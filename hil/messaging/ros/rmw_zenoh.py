"""The wire layout of ROS 2's rmw_zenoh (ros2/rmw_zenoh docs/design.md and its
``liveliness_utils``/``qos``/``attachment_helpers`` sources), as plain data and functions:

* key expressions of topics and services: ``<domain>/<fully qualified name, no leading
  slash>/<type name, dds_ form>/<RIHS01 type hash>``;
* liveliness tokens of nodes (NN), publishers (MP), subscriptions (MS), service servers
  (SS) and clients (SC), with names mangled (``/`` -> ``%``) and QoS in its compact form;
* the 33-byte attachment on every put, query and reply (sequence number, source
  timestamp, GID), and the GID itself: XXH3-128 of the entity's liveliness key expression.

Nothing here opens Zenoh: :mod:`hil.messaging.ros.node` does.
"""

from __future__ import annotations

import enum
import struct
import time
from dataclasses import dataclass

import xxhash

#: the hermetic prefix of every liveliness token (``*`` and ``**`` never match it)
ADMIN_SPACE = "@ros2_lv"
#: an empty namespace or enclave in a token: Zenoh key chunks cannot be empty
EMPTY = "%"
ATTACHMENT = struct.Struct("<qqB16s")
GID_SIZE = 16


class EntityKind(enum.Enum):
    NODE = "NN"
    PUBLISHER = "MP"
    SUBSCRIPTION = "MS"
    SERVICE = "SS"
    CLIENT = "SC"


class Reliability(enum.IntEnum):     # rmw_qos_reliability_policy_e
    SYSTEM_DEFAULT = 0
    RELIABLE = 1
    BEST_EFFORT = 2


class Durability(enum.IntEnum):      # rmw_qos_durability_policy_e
    SYSTEM_DEFAULT = 0
    TRANSIENT_LOCAL = 1
    VOLATILE = 2


class History(enum.IntEnum):         # rmw_qos_history_policy_e
    SYSTEM_DEFAULT = 0
    KEEP_LAST = 1
    KEEP_ALL = 2


@dataclass(frozen=True)
class QoS:
    """The QoS of an entity, as rmw_zenoh adapts it (system defaults resolved). Deadline,
    lifespan and liveliness are rmw_zenoh's defaults (infinite, automatic): it implements
    none of them, and hil's entities ask for none."""

    reliability: Reliability = Reliability.RELIABLE
    durability: Durability = Durability.VOLATILE
    history: History = History.KEEP_LAST
    depth: int = 42

    def to_keyexpr(self) -> str:
        """rmw_zenoh's ``qos_to_keyexpr``: each field that differs from rmw_zenoh's default
        (reliable, volatile, keep last 42) is written, the rest left empty."""
        default = QoS()
        part = lambda value, base: "" if value == base else str(int(value))  # noqa: E731
        return (f"{part(self.reliability, default.reliability)}:"
                f"{part(self.durability, default.durability)}:"
                f"{part(self.history, default.history)},{part(self.depth, default.depth)}:"
                ",:,:,,")

    @classmethod
    def from_keyexpr(cls, text: str) -> QoS:
        """The inverse of :meth:`to_keyexpr`; ValueError for a malformed one."""
        parts = text.split(":")
        if len(parts) != 6 or len(parts[2].split(",")) != 2:
            raise ValueError(f"malformed rmw_zenoh QoS {text!r} (expected 6 ':' parts)")
        default = cls()
        history, depth = parts[2].split(",")
        try:
            return cls(Reliability(int(parts[0])) if parts[0] else default.reliability,
                       Durability(int(parts[1])) if parts[1] else default.durability,
                       History(int(history)) if history else default.history,
                       int(depth) if depth else default.depth)
        except ValueError as exc:
            raise ValueError(f"malformed rmw_zenoh QoS {text!r}: {exc}") from None


#: rclcpp/rcl profiles hil's entities use, after rmw_zenoh's adaptation
DEFAULT_QOS = QoS(depth=10)                                             # rmw_qos_profile_default
SERVICES_QOS = QoS(depth=10)                                    # rmw_qos_profile_services_default
LATCHED_QOS = QoS(durability=Durability.TRANSIENT_LOCAL, depth=1)       # e.g. robot_description
ACTION_STATUS_QOS = QoS(durability=Durability.TRANSIENT_LOCAL, depth=1)  # rcl_action status
CLOCK_QOS = QoS(reliability=Reliability.BEST_EFFORT, depth=1)           # rclcpp::ClockQoS


def mangle(name: str) -> str:
    """A name as one key chunk: every ``/`` becomes ``%`` (rmw_zenoh's ``mangle_name``)."""
    return name.replace("/", "%")


def demangle(chunk: str) -> str:
    return chunk.replace("%", "/")


def fully_qualified(namespace: str, name: str) -> str:
    """``/ns/name`` for a relative ``name`` in ``namespace`` (``/`` or ``/robot1``); an
    absolute ``name`` stays as it is."""
    if name.startswith("/"):
        return name
    return f"{namespace.rstrip('/')}/{name}"


def topic_keyexpr(domain_id: int, name: str, type_name: str, type_hash: str) -> str:
    """The key expression of a topic or service (``name`` fully qualified)."""
    return f"{domain_id}/{name.strip('/')}/{type_name}/{type_hash}"


@dataclass(frozen=True)
class TopicInfo:
    """What a publisher, subscription, service or client carries beyond its node."""

    name: str                  # fully qualified
    type_name: str             # dds_ form
    type_hash: str             # RIHS01_...
    qos: QoS = DEFAULT_QOS


@dataclass(frozen=True)
class Entity:
    """A ROS graph entity, as its liveliness token describes it."""

    domain_id: int
    session_id: str            # the Zenoh session's id, as text
    node_id: int
    entity_id: int
    kind: EntityKind
    namespace: str             # "/" or "/robot1"
    node_name: str
    enclave: str = ""
    topic: TopicInfo | None = None

    def token(self) -> str:
        """The liveliness key expression (rmw_zenoh's ``Entity`` constructor)."""
        chunks = [ADMIN_SPACE, str(self.domain_id), self.session_id, str(self.node_id),
                  str(self.entity_id), self.kind.value, mangle(self.enclave) or EMPTY,
                  mangle(self.namespace) or EMPTY, mangle(self.node_name)]
        if self.topic is not None:
            chunks += [mangle(self.topic.name), mangle(self.topic.type_name),
                       mangle(self.topic.type_hash), self.topic.qos.to_keyexpr()]
        return "/".join(chunks)

    def gid(self) -> bytes:
        """The entity's 16-byte GID: XXH3-128 of its token, low 64 bits first, each half in
        the host's (little-endian) byte order, as rmw_zenoh copies them."""
        digest = xxhash.xxh3_128_intdigest(self.token().encode())
        return struct.pack("<QQ", digest & (2 ** 64 - 1), digest >> 64)

    def keyexpr(self) -> str:
        """The key expression its data travels on."""
        if self.topic is None:
            raise ValueError("a node has no data key expression")
        return topic_keyexpr(self.domain_id, self.topic.name, self.topic.type_name,
                             self.topic.type_hash)

    @classmethod
    def from_token(cls, token: str) -> Entity:
        """Parse a liveliness token; ValueError naming what is wrong."""
        parts = token.split("/")
        if len(parts) not in (9, 13) or parts[0] != ADMIN_SPACE or "" in parts:
            raise ValueError(f"not an rmw_zenoh liveliness token: {token!r}")
        try:
            kind = EntityKind(parts[5])
        except ValueError:
            raise ValueError(f"unknown entity kind {parts[5]!r} in {token!r}") from None
        if (kind is EntityKind.NODE) != (len(parts) == 9):
            raise ValueError(f"a {kind.name.lower()} token has {len(parts)} parts: {token!r}")
        topic = None
        if len(parts) == 13:
            topic = TopicInfo(demangle(parts[9]), demangle(parts[10]), demangle(parts[11]),
                              QoS.from_keyexpr(parts[12]))
        namespace = demangle(parts[7])
        return cls(int(parts[1]), parts[2], int(parts[3]), int(parts[4]), kind,
                   namespace, demangle(parts[8]),
                   "" if parts[6] == EMPTY else demangle(parts[6]), topic)


@dataclass(frozen=True)
class Attachment:
    """What rides beside every put, query and reply: 8 bytes sequence number (int64, little
    endian), 8 bytes source timestamp (ns since the epoch, int64 little endian), 1 byte GID
    length (16), 16 bytes GID: 33 bytes."""

    sequence_number: int
    source_timestamp: int
    gid: bytes

    def pack(self) -> bytes:
        return ATTACHMENT.pack(self.sequence_number, self.source_timestamp, GID_SIZE, self.gid)

    @classmethod
    def unpack(cls, data: bytes | None) -> Attachment:
        """Parse one; ValueError for anything but the 33-byte layout."""
        if data is None:
            raise ValueError("no attachment (rmw_zenoh sends sequence number, timestamp, GID)")
        if len(data) != ATTACHMENT.size:
            raise ValueError(f"an attachment of {len(data)} bytes (rmw_zenoh: {ATTACHMENT.size})")
        sequence, stamp, length, gid = ATTACHMENT.unpack(data)
        if length != GID_SIZE:
            raise ValueError(f"a GID of {length} bytes in the attachment (rmw_zenoh: {GID_SIZE})")
        return cls(sequence, stamp, gid)

    @classmethod
    def now(cls, sequence_number: int, gid: bytes) -> Attachment:
        return cls(sequence_number, time.time_ns(), gid)


def liveliness_query(domain_id: int) -> str:
    """What a context queries (and subscribes to) for the whole graph of a domain."""
    return f"{ADMIN_SPACE}/{domain_id}/**"


__all__ = ["ACTION_STATUS_QOS", "ADMIN_SPACE", "Attachment", "CLOCK_QOS", "DEFAULT_QOS",
           "Durability", "Entity", "EntityKind", "History", "LATCHED_QOS", "QoS",
           "Reliability", "SERVICES_QOS", "TopicInfo", "fully_qualified", "liveliness_query",
           "mangle", "topic_keyexpr"]
