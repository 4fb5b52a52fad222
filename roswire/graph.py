"""The ROS graph as seen through liveliness tokens: pure state, no I/O (rmw_zenoh.md §3).

Feed it token PUTs and DELETEs with :meth:`Graph.apply`; it answers what nodes, topics and
services exist and returns the :class:`GraphEvent`\\ s each change caused. Nodes are identified
by ``(zid, nid)``; like rmw_zenoh's graph cache, a node exists as soon as its ``NN`` token or any
of its endpoint tokens does, and disappears with the last of them.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from enum import Enum

from fleetlink.roswire.tokens import EndpointInfo, Entity, EntityKind, NodeInfo, node_token, parse_token


class EventKind(Enum):
    """Whether a graph entity appeared or disappeared."""

    APPEARED = "appeared"
    DISAPPEARED = "disappeared"


@dataclass(frozen=True)
class GraphEvent:
    """A node or endpoint that appeared in or disappeared from the graph."""

    kind: EventKind
    entity: Entity


@dataclass(frozen=True)
class TopicInfo:
    """A topic (or service) name with what is known about it across all endpoints."""

    name: str
    types: tuple[str, ...]
    publishers: tuple[EndpointInfo, ...] = ()
    subscribers: tuple[EndpointInfo, ...] = ()


@dataclass
class _Node:
    info: NodeInfo
    has_token: bool = False
    endpoints: dict[str, EndpointInfo] = field(default_factory=dict)


class Graph:
    """Graph state built from liveliness tokens."""

    def __init__(self, own_zid: str | None = None, domain: int | None = None) -> None:
        self.own_zid = own_zid
        self.domain = domain
        self._nodes: dict[tuple[str, int], _Node] = {}
        self._entities: dict[str, Entity] = {}
        self.ignored = 0
        """Tokens skipped because they belong to ``own_zid`` or another domain."""

    # --- updates ----------------------------------------------------------------------------

    def apply(self, kind: str, key: str) -> list[GraphEvent]:
        """Apply a token ``"put"`` or ``"delete"``; a malformed PUT raises TokenError."""
        if kind == "put":
            return self.put(key)
        if kind == "delete":
            return self.delete(key)
        raise ValueError(f"token change kind must be 'put' or 'delete', not {kind!r}")

    def put(self, key: str) -> list[GraphEvent]:
        """Add a token's entity (and its node if new); the events caused, none for a known or ignored token.

        A malformed token raises :class:`TokenError`.
        """
        if key in self._entities:
            return []
        entity = parse_token(key)
        if (self.own_zid is not None and entity.zid == self.own_zid) or (
            self.domain is not None and entity.domain != self.domain
        ):
            self.ignored += 1
            return []
        events: list[GraphEvent] = []
        node = self._nodes.get(entity.node_id)
        if isinstance(entity, NodeInfo):
            if node is None:
                self._nodes[entity.node_id] = _Node(entity, has_token=True)
                events.append(GraphEvent(EventKind.APPEARED, entity))
            else:
                node.info = entity
                node.has_token = True
        else:
            if node is None:
                node = _Node(_implicit_node(entity))
                self._nodes[entity.node_id] = node
                events.append(GraphEvent(EventKind.APPEARED, node.info))
            node.endpoints[key] = entity
            events.append(GraphEvent(EventKind.APPEARED, entity))
        self._entities[key] = entity
        return events

    def delete(self, key: str) -> list[GraphEvent]:
        """Remove the entity of a token (and its node with its last token); the events it caused."""
        entity = self._entities.pop(key, None)
        if entity is None:
            return []
        node = self._nodes[entity.node_id]
        events: list[GraphEvent] = []
        if isinstance(entity, NodeInfo):
            node.has_token = False
        else:
            del node.endpoints[key]
            events.append(GraphEvent(EventKind.DISAPPEARED, entity))
        if not node.has_token and not node.endpoints:
            del self._nodes[entity.node_id]
            events.append(GraphEvent(EventKind.DISAPPEARED, node.info))
        return events

    def drop_session(self, zid: str) -> list[GraphEvent]:
        """Forget every entity of one session (as if all its tokens were deleted)."""
        events: list[GraphEvent] = []
        for key in [k for k, e in self._entities.items() if e.zid == zid]:
            events.extend(self.delete(key))
        return events

    # --- queries ----------------------------------------------------------------------------

    def __len__(self) -> int:
        return len(self._entities)

    def __contains__(self, key: object) -> bool:
        return key in self._entities

    def nodes(self) -> list[NodeInfo]:
        """Every node, sorted by fully qualified name."""
        return sorted((n.info for n in self._nodes.values()), key=lambda i: (i.fqn, i.zid, i.nid))

    def endpoints(self, kinds: Iterable[EntityKind] | None = None) -> list[EndpointInfo]:
        """Every endpoint of the given kinds (all when None), sorted by topic, kind and id."""
        wanted = set(kinds) if kinds is not None else None
        found = [
            e
            for e in self._entities.values()
            if isinstance(e, EndpointInfo) and (wanted is None or e.kind in wanted)
        ]
        return sorted(found, key=lambda e: (e.topic, e.kind.value, e.zid, e.eid))

    def node_endpoints(self, node_id: tuple[str, int]) -> list[EndpointInfo]:
        """The endpoints of one node, by entity id (empty for an unknown node)."""
        node = self._nodes.get(node_id)
        return [] if node is None else sorted(node.endpoints.values(), key=lambda e: e.eid)

    def topics(self) -> dict[str, TopicInfo]:
        """Topic name -> types, publishers and subscribers (MP/MS endpoints)."""
        return _collect(self.endpoints((EntityKind.PUBLISHER, EntityKind.SUBSCRIPTION)), EntityKind.PUBLISHER)

    def services(self) -> dict[str, TopicInfo]:
        """Service name -> types, servers (``publishers``) and clients (``subscribers``)."""
        return _collect(
            self.endpoints((EntityKind.SERVICE_SERVER, EntityKind.SERVICE_CLIENT)), EntityKind.SERVICE_SERVER
        )

    def in_namespace(self, namespace: str) -> list[Entity]:
        """Every node and endpoint whose namespace is ``namespace`` or below it."""
        prefix = namespace.rstrip("/") + "/"
        return [
            e
            for e in self._entities.values()
            if e.namespace == namespace or e.namespace.startswith(prefix) or namespace == "/"
        ]


def _implicit_node(endpoint: EndpointInfo) -> NodeInfo:
    key = node_token(
        endpoint.domain,
        endpoint.zid,
        endpoint.nid,
        endpoint.namespace,
        endpoint.node_name,
        enclave=endpoint.enclave,
    )
    return NodeInfo(
        endpoint.domain,
        endpoint.zid,
        endpoint.nid,
        endpoint.enclave,
        endpoint.namespace,
        endpoint.node_name,
        key,
    )


def _collect(endpoints: list[EndpointInfo], first_kind: EntityKind) -> dict[str, TopicInfo]:
    grouped: dict[str, tuple[set[str], list[EndpointInfo], list[EndpointInfo]]] = {}
    for ep in endpoints:
        types, first, second = grouped.setdefault(ep.topic, (set(), [], []))
        types.add(ep.ros_type)
        (first if ep.kind is first_kind else second).append(ep)
    return {
        name: TopicInfo(name, tuple(sorted(types)), tuple(first), tuple(second))
        for name, (types, first, second) in sorted(grouped.items())
    }
