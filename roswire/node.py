"""``RosNode``: a ROS 2 node on the rmw_zenoh wire, without ROS.

A node owns a zenoh session (or borrows one), declares its ``NN`` liveliness token, hands out
entity ids and creates publishers and subscribers. Nothing touches the network before
:meth:`RosNode.start`; :meth:`RosNode.stop` undeclares everything the node created.
"""

from __future__ import annotations

import itertools
import logging
import threading
from collections.abc import Callable
from types import TracebackType
from typing import TYPE_CHECKING, Any, Protocol

import zenoh

from fleetlink.roswire.attachment import AttachmentVersion
from fleetlink.roswire.errors import RoswireError
from fleetlink.roswire.names import mangle, resolve_topic, validate_namespace, validate_node_name
from fleetlink.roswire.qos import DEFAULT, QoS
from fleetlink.roswire.session import open_session
from fleetlink.roswire.tokens import EntityKind, endpoint_token, node_token
from fleetlink.schemas.typehash import type_hash as compute_type_hash
from fleetlink.schemas.typestore import Distro

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

    from fleetlink.roswire.publisher import RosPublisher
    from fleetlink.roswire.subscriber import RosSample, RosSubscriber

log = logging.getLogger(__name__)

# rmw_zenoh takes node and entity ids from one counter per context; only uniqueness within a
# session matters, and one counter per process guarantees it even for shared sessions.
_ids = itertools.count(0)
_ids_lock = threading.Lock()


def next_entity_id() -> int:
    """A node or entity id not used before in this process."""
    with _ids_lock:
        return next(_ids)


class Entity(Protocol):
    """Anything a node stops together with itself."""

    def stop(self) -> None:
        """Undeclare what the entity declared."""


class RosNode:
    """A ROS 2 node on the rmw_zenoh wire: its session, its ``NN`` token, and the entities it created."""

    def __init__(
        self,
        name: str,
        namespace: str = "/",
        *,
        domain_id: int = 0,
        enclave: str = "/",
        config: zenoh.Config | None = None,
        session: zenoh.Session | None = None,
        typestore: Typestore | None = None,
        distro: Distro = "jazzy",
        attachment_version: AttachmentVersion = 2,
    ) -> None:
        self.name = validate_node_name(name)
        self.namespace = validate_namespace(namespace)
        self.domain_id = domain_id
        self.enclave = enclave
        self.typestore = typestore
        self.distro = distro
        self.attachment_version: AttachmentVersion = attachment_version
        self._config = config
        self._borrowed = session
        self._session: zenoh.Session | None = None
        self._token: zenoh.LivelinessToken | None = None
        self._entities: list[Entity] = []
        self._hashes: dict[str, str] = {}
        self._lock = threading.Lock()
        self.nid = -1
        self.token_key = ""

    # --- lifecycle --------------------------------------------------------------------------

    def start(self) -> RosNode:
        """Open a session (or use the one lent to the node) and declare the ``NN`` token; returns self."""
        if self._session is not None:
            return self
        if self._borrowed is not None:
            self._session = self._borrowed
        else:
            if self._config is None:
                raise RoswireError(f"node {self.name!r}: give either a zenoh config or a session")
            self._session = open_session(self._config)
        self.nid = next_entity_id()
        self.token_key = node_token(
            self.domain_id, self.zid, self.nid, self.namespace, self.name, enclave=self.enclave
        )
        self._token = self._session.liveliness().declare_token(self.token_key)
        log.debug("node started token=%s", self.token_key)
        return self

    def stop(self) -> None:
        """Stop every entity of the node, undeclare its token and close the session if the node opened it."""
        with self._lock:
            entities, self._entities = self._entities, []
        for entity in reversed(entities):
            try:
                entity.stop()
            except zenoh.ZError as exc:  # a closed session must not prevent the rest of cleanup
                log.warning("node=%s stopping entity failed: %s", self.name, exc)
        if self._token is not None:
            try:
                self._token.undeclare()
            except zenoh.ZError as exc:
                log.debug("node=%s token undeclare failed: %s", self.name, exc)
            self._token = None
        if self._session is not None and self._borrowed is None:
            self._session.close()
        self._session = None

    def __enter__(self) -> RosNode:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    # --- accessors --------------------------------------------------------------------------

    @property
    def session(self) -> zenoh.Session:
        """The node's zenoh session; raises ``RoswireError`` before :meth:`start`."""
        if self._session is None:
            raise RoswireError(f"node {self.name!r} is not started")
        return self._session

    @property
    def zid(self) -> str:
        """The session's zenoh id as hex text."""
        return str(self.session.zid())

    @property
    def started(self) -> bool:
        """Whether the node has a session."""
        return self._session is not None

    def resolve(self, topic: str) -> str:
        """The fully qualified name of ``topic`` relative to this node's namespace and name."""
        return resolve_topic(topic, self.namespace, self.name)

    def type_hash(self, typename: str) -> str:
        """The hash of ``typename`` for this node's distro, from its type store (cached)."""
        cached = self._hashes.get(typename)
        if cached is not None:
            return cached
        if self.typestore is None:
            raise RoswireError(f"node {self.name!r}: no type store to compute the hash of {typename}")
        value = compute_type_hash(self.typestore, typename, self.distro)
        self._hashes[typename] = value
        return value

    def endpoint_token(
        self,
        kind: EntityKind,
        topic: str,
        typename: str,
        *,
        type_hash: str,
        qos: QoS,
        eid: int | None = None,
    ) -> str:
        """The liveliness key of one of this node's endpoints (under a new entity id unless ``eid``)."""
        return endpoint_token(
            domain=self.domain_id,
            zid=self.zid,
            nid=self.nid,
            eid=next_entity_id() if eid is None else eid,
            kind=kind,
            namespace=self.namespace,
            node_name=self.name,
            topic=topic,
            typename=typename,
            type_hash=type_hash,
            qos=qos,
            enclave=self.enclave,
        )

    def announced(self, kind: EntityKind, topic: str, timeout: float) -> bool:
        """Whether any endpoint of ``kind`` on ``topic`` (any type) answers a liveliness query."""
        pattern = f"@ros2_lv/{self.domain_id}/*/*/*/{kind.value}/*/*/*/{mangle(topic)}/**"
        replies = self.session.liveliness().get(pattern, timeout=timeout)
        return any(reply.ok is not None for reply in replies)

    def adopt(self, entity: Entity) -> None:
        """Stop ``entity`` together with the node."""
        with self._lock:
            self._entities.append(entity)

    def forget(self, entity: Entity) -> None:
        """No longer stop ``entity`` with the node (it stopped on its own)."""
        with self._lock:
            if entity in self._entities:
                self._entities.remove(entity)

    # --- factories --------------------------------------------------------------------------

    def create_publisher(self, topic: str, typename: str, qos: QoS = DEFAULT, **kwargs: Any) -> RosPublisher:
        """A started :class:`RosPublisher` on ``topic``; ``kwargs`` go to its constructor."""
        from fleetlink.roswire.publisher import RosPublisher

        return RosPublisher(self, topic, typename, qos, **kwargs).start()

    def create_subscriber(
        self,
        topic: str,
        typename: str | None,
        callback: Callable[[RosSample], object],
        qos: QoS = DEFAULT,
        **kwargs: Any,
    ) -> RosSubscriber:
        """A started :class:`RosSubscriber` on ``topic``; ``kwargs`` go to its constructor."""
        from fleetlink.roswire.subscriber import RosSubscriber

        return RosSubscriber(self, topic, typename, callback, qos, **kwargs).start()
