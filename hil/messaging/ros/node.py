"""A ROS 2 node on Zenoh as rmw_zenoh makes one: a context (one Zenoh session), nodes
with liveliness tokens, and their publishers, service servers and clients, each with its
own token, GID and sequence numbers (:mod:`hil.messaging.ros.rmw_zenoh`).

Payloads are CDR bytes (:mod:`hil.messaging.cdr`); nothing here knows a message type.
"""

from __future__ import annotations

import itertools
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import zenoh
import zenoh.ext

from hil.messaging.ros.interfaces import Interface
from hil.messaging.ros.rmw_zenoh import (
    DEFAULT_QOS, SERVICES_QOS, Attachment, Durability, Entity, EntityKind, QoS, Reliability,
    TopicInfo, fully_qualified, liveliness_query,
)

#: rmw_zenoh's sample miss detection heartbeat of reliable transient-local publishers (s)
MISS_DETECTION_HEARTBEAT = 0.5
#: how long a request waits for its reply: rmw_zenoh asks for no limit (an action's
#: get_result is answered when the goal ends, however long it runs); this is ten years
NO_LIMIT = 10 * 365 * 86400.0


class RosContext:
    """One ROS 2 context: a Zenoh session and the ids of the entities declared on it."""

    def __init__(self, session: zenoh.Session, domain_id: int = 0, enclave: str = ""):
        self.session, self.domain_id, self.enclave = session, domain_id, enclave
        self.session_id = str(session.zid())
        self._ids = itertools.count()

    def next_id(self) -> int:
        return next(self._ids)

    def node(self, name: str, namespace: str = "/") -> RosNode:
        return RosNode(self, name, namespace)

    def graph(self, timeout: float = 2.0) -> list[Entity]:
        """Every entity of this domain alive now (a liveliness query, as a context makes
        at start); tokens that do not parse are left out."""
        entities = []
        for reply in self.session.liveliness().get(liveliness_query(self.domain_id),
                                                   timeout=timeout):
            if reply.ok is not None:
                try:
                    entities.append(Entity.from_token(str(reply.ok.key_expr)))
                except ValueError:
                    continue
        return entities

    def wait_for(self, kind: EntityKind, name: str, timeout: float) -> bool:
        """Whether an entity of ``kind`` on ``name`` (fully qualified) appears in the graph
        within ``timeout``."""
        deadline = time.monotonic() + timeout
        while True:
            if any(e.kind is kind and e.topic is not None and e.topic.name == name
                   for e in self.graph(min(2.0, max(0.1, deadline - time.monotonic())))):
                return True
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.1)


class RosNode:
    """A ROS 2 node: its NN token, and the entities declared through it."""

    def __init__(self, context: RosContext, name: str, namespace: str = "/"):
        if not namespace.startswith("/"):
            raise ValueError(f"a ROS namespace starts with '/': {namespace!r}")
        self.context, self.name, self.namespace = context, name, namespace.rstrip("/") or "/"
        self.node_id = context.next_id()
        self.entity = self._entity(EntityKind.NODE, None, self.node_id)
        self._token = context.session.liveliness().declare_token(self.entity.token())
        self._closables: list = []
        #: the interfaces of every entity declared through the node, by type name (what its
        #: type description service describes)
        self.interfaces: dict[str, Interface] = {}

    def _entity(self, kind: EntityKind, topic: TopicInfo | None, entity_id: int) -> Entity:
        return Entity(self.context.domain_id, self.context.session_id, self.node_id,
                      entity_id, kind, self.namespace, self.name, self.context.enclave, topic)

    def _declare(self, kind: EntityKind, name: str, interface: Interface,
                 qos: QoS) -> tuple[Entity, zenoh.LivelinessToken]:
        self.interfaces[interface.name] = interface
        topic = TopicInfo(fully_qualified(self.namespace, name), interface.type_name,
                          interface.type_hash, qos)
        entity = self._entity(kind, topic, self.context.next_id())
        return entity, self.context.session.liveliness().declare_token(entity.token())

    def publisher(self, name: str, interface: Interface, qos: QoS = DEFAULT_QOS) -> RosPublisher:
        publisher = RosPublisher(self, *self._declare(EntityKind.PUBLISHER, name, interface, qos))
        self._closables.append(publisher)
        return publisher

    def service(self, name: str, interface: Interface,
                handler: Callable[[ServiceRequest], None],
                qos: QoS = SERVICES_QOS) -> RosService:
        """A service server: ``handler`` gets each request and answers it through
        :meth:`ServiceRequest.reply`, at once or later from any thread."""
        service = RosService(self, handler,
                             *self._declare(EntityKind.SERVICE, name, interface, qos))
        self._closables.append(service)
        return service

    def client(self, name: str, interface: Interface, qos: QoS = SERVICES_QOS) -> RosClient:
        client = RosClient(self, *self._declare(EntityKind.CLIENT, name, interface, qos))
        self._closables.append(client)
        return client

    def subscription(self, name: str, interface: Interface,
                     callback: Callable[[bytes, Attachment | None], None],
                     qos: QoS = DEFAULT_QOS) -> RosSubscription:
        subscription = RosSubscription(
            self, callback, *self._declare(EntityKind.SUBSCRIPTION, name, interface, qos))
        self._closables.append(subscription)
        return subscription

    def close(self) -> None:
        """Undeclare every entity, then the node."""
        for closable in reversed(self._closables):
            closable.close()
        self._closables.clear()
        self._token.undeclare()


class _Declared:
    """An entity's liveliness token and what it declared on Zenoh, undeclared once (by
    whoever closes first: its owner or its node)."""

    def __init__(self, entity: Entity, token: zenoh.LivelinessToken):
        self.entity, self._token, self._closed = entity, token, False

    def close(self) -> None:
        if self._closed:
            return
        self._closed = True
        self._token.undeclare()
        self._undeclare()

    def _undeclare(self) -> None:
        """Undeclare what the entity declared besides its token."""


class RosPublisher(_Declared):
    """Puts CDR payloads with rmw_zenoh's attachment; transient-local ones keep the last
    ``depth`` samples for late subscribers in a Zenoh advanced publisher's cache."""

    def __init__(self, node: RosNode, entity: Entity, token: zenoh.LivelinessToken):
        super().__init__(entity, token)
        self.gid = entity.gid()
        self._sequence = itertools.count(1)       # rmw_zenoh's first sample is number 1
        self._lock = threading.Lock()
        qos = entity.topic.qos
        reliability = (zenoh.Reliability.RELIABLE if qos.reliability is Reliability.RELIABLE
                       else zenoh.Reliability.BEST_EFFORT)
        session = node.context.session
        if qos.durability is Durability.TRANSIENT_LOCAL:
            detection = (zenoh.ext.MissDetectionConfig(
                sporadic_heartbeat=MISS_DETECTION_HEARTBEAT)
                if qos.reliability is Reliability.RELIABLE else None)
            self._publisher = zenoh.ext.declare_advanced_publisher(
                session, entity.keyexpr(), reliability=reliability,
                congestion_control=zenoh.CongestionControl.DROP,
                cache=zenoh.ext.CacheConfig(max_samples=qos.depth),
                sample_miss_detection=detection, publisher_detection=True)
        else:
            self._publisher = session.declare_publisher(
                entity.keyexpr(), reliability=reliability,
                congestion_control=zenoh.CongestionControl.DROP)

    def put(self, payload: bytes) -> None:
        with self._lock:      # sequence numbers in the order the samples leave
            attachment = Attachment.now(next(self._sequence), self.gid)
            self._publisher.put(payload, attachment=attachment.pack())

    def _undeclare(self) -> None:
        self._publisher.undeclare()


@dataclass
class ServiceRequest:
    """One request to a service server: its payload and attachment, and how to answer."""

    payload: bytes
    attachment: Attachment
    _query: zenoh.Query
    _service: RosService

    def reply(self, payload: bytes) -> None:
        """Answer with ``payload``, echoing the request's sequence number and client GID."""
        attachment = Attachment.now(self.attachment.sequence_number, self.attachment.gid)
        try:
            self._query.reply(self._query.key_expr, payload, attachment=attachment.pack())
        finally:
            self._service.done(self)

    def reply_error(self, text: str) -> None:
        """Answer with a Zenoh error (an rmw_zenoh client logs it and takes no response)."""
        try:
            self._query.reply_err(text)
        finally:
            self._service.done(self)


class RosService(_Declared):
    """A service server: a complete queryable on the service's key expression."""

    def __init__(self, node: RosNode, handler: Callable[[ServiceRequest], None],
                 entity: Entity, token: zenoh.LivelinessToken):
        super().__init__(entity, token)
        self._handler = handler
        self._pending: dict[int, ServiceRequest] = {}
        self._lock = threading.Lock()
        self._queryable = node.context.session.declare_queryable(
            entity.keyexpr(), zenoh.handlers.Callback(self._on_query, indirect=False),
            complete=True)

    def _on_query(self, query: zenoh.Query) -> None:
        try:
            attachment = Attachment.unpack(
                query.attachment.to_bytes() if query.attachment is not None else None)
        except ValueError as exc:
            query.reply_err(f"{self.entity.topic.name}: {exc}")
            return
        payload = query.payload.to_bytes() if query.payload is not None else b""
        request = ServiceRequest(payload, attachment, query, self)
        with self._lock:
            self._pending[id(request)] = request    # the query stays open until answered
        self._handler(request)

    def done(self, request: ServiceRequest) -> None:
        with self._lock:
            self._pending.pop(id(request), None)
        request._query.drop()

    def _undeclare(self) -> None:
        """Stop serving; requests still waiting get an error reply saying so."""
        with self._lock:
            waiting = list(self._pending.values())
        for request in waiting:
            request.reply_error(f"{self.entity.topic.name}: the server is shutting down")
        self._queryable.undeclare()


class ServiceError(RuntimeError):
    """A service call got no usable reply."""


class RosClient(_Declared):
    """A service client: each call is a query with the client's GID and next sequence
    number, sent to every complete server (target ALL_COMPLETE, no consolidation)."""

    def __init__(self, node: RosNode, entity: Entity, token: zenoh.LivelinessToken):
        super().__init__(entity, token)
        self.session = node.context.session
        self.gid = entity.gid()
        self._sequence = itertools.count(1)
        self._lock = threading.Lock()

    def call(self, payload: bytes, timeout: float = NO_LIMIT) -> tuple[bytes, Attachment]:
        """The response to ``payload``; ServiceError if none comes within ``timeout``, the
        server answers with an error, or the reply is not for this request."""
        with self._lock:
            sequence = next(self._sequence)
        attachment = Attachment.now(sequence, self.gid)
        replies = self.session.get(
            self.entity.keyexpr(), payload=payload, attachment=attachment.pack(),
            target=zenoh.QueryTarget.ALL_COMPLETE, consolidation=zenoh.ConsolidationMode.NONE,
            timeout=timeout)
        for reply in replies:
            if reply.err is not None:
                raise ServiceError(f"{self.entity.topic.name}: "
                                   f"{reply.err.payload.to_bytes().decode(errors='replace')}")
            answer = Attachment.unpack(reply.ok.attachment.to_bytes()
                                       if reply.ok.attachment is not None else None)
            if answer.sequence_number != sequence or answer.gid != self.gid:
                raise ServiceError(f"{self.entity.topic.name}: a reply for sequence number "
                                   f"{answer.sequence_number}, not {sequence}")
            return reply.ok.payload.to_bytes(), answer
        raise ServiceError(f"no server answered on {self.entity.topic.name} within "
                           f"{timeout:g} s")


class RosSubscription(_Declared):
    """A subscription: ``callback(payload, attachment)`` in Zenoh's thread for each sample
    (attachment None where the publisher sent none or a malformed one)."""

    def __init__(self, node: RosNode, callback: Callable[[bytes, Attachment | None], None],
                 entity: Entity, token: zenoh.LivelinessToken):
        super().__init__(entity, token)
        self._callback = callback
        session = node.context.session
        handler = zenoh.handlers.Callback(self._on_sample, indirect=False)
        if entity.topic.qos.durability is Durability.TRANSIENT_LOCAL:
            self._subscriber = zenoh.ext.declare_advanced_subscriber(
                session, entity.keyexpr(), handler,
                history=zenoh.ext.HistoryConfig(detect_late_publishers=True,
                                                max_samples=entity.topic.qos.depth),
                subscriber_detection=True)
        else:
            self._subscriber = session.declare_subscriber(entity.keyexpr(), handler)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        try:
            attachment = Attachment.unpack(sample.attachment.to_bytes()
                                           if sample.attachment is not None else None)
        except ValueError:
            attachment = None
        self._callback(sample.payload.to_bytes(), attachment)

    def _undeclare(self) -> None:
        self._subscriber.undeclare()


__all__ = ["NO_LIMIT", "RosClient", "RosContext", "RosNode", "RosPublisher", "RosService",
           "RosSubscription", "ServiceError", "ServiceRequest"]
