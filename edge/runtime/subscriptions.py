"""Discovered publishers -> one ``RosSubscriber`` per topic that feeds at least one mapping.

A ``GraphWatcher`` reports every publisher (``MP`` token) with its topic and type. Whenever the
graph or the mapping table changes, the wanted subscriptions are recomputed (``plan``, pure)
and the difference applied on a small thread of its own (never on a Zenoh callback thread):
new topics are subscribed, topics no mapping wants any more are dropped. A topic is subscribed
with the type a mapping declares, else the type its publishers announce (any type, ``*``, when
they disagree), and always with any type hash (``*``): a robot built against a slightly
different definition is still received, and the hash each sample really carried goes into its
record's headers. A mapping that declares its type subscribes as soon as its topic is known
(a robot registered), before any publisher shows up.

Every subscription is a key expression of the edge's native data plane
(``dataplane.NativeSource``): one bounded intake for all of them, no thread per subscription, so
an idle subscription costs nothing but its entry in the router. The liveliness token of a
subscription (``MS``, so that ``ros2 topic info`` counts the edge) is declared on the edge's
Python session, as its node is.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Collection, Mapping
from dataclasses import dataclass
from types import TracebackType

import zenoh

from fleetlink.edge.errors import MappingError
from fleetlink.edge.mapping import MappingTable, TopicPattern
from fleetlink.edge.runtime.dataplane import NativeSource
from fleetlink.roswire.discovery import GraphWatcher
from fleetlink.roswire.errors import RoswireError
from fleetlink.roswire.graph import EventKind, GraphEvent
from fleetlink.roswire.names import data_key_expr
from fleetlink.roswire.node import RosNode, next_entity_id
from fleetlink.roswire.qos import DEFAULT
from fleetlink.roswire.tokens import EndpointInfo, EntityKind, endpoint_token
from fleetlink.schemas.errors import SchemaError

log = logging.getLogger(__name__)


def eager_topics(table: MappingTable) -> dict[str, str]:
    """Concrete topics of mappings that declare a ROS type (robot templates bound to each
    registered robot, literal site-level patterns) -> that type."""
    out: dict[str, str] = {}
    for info in table.list():
        if info.ros_type is None:
            continue
        pattern = TopicPattern.parse(info.source)
        bindings = [pattern.bind({"robot": robot}) for robot in info.robots] if info.robot_type else [pattern]
        for bound in bindings:
            if bound.is_literal:
                out.setdefault(bound.text, info.ros_type)
    return out


def plan(
    publishers: Mapping[str, Collection[str]],
    table: MappingTable,
    eager: Mapping[str, str] | None = None,
) -> dict[str, str | None]:
    """The wanted subscriptions: topic -> ROS type to subscribe with (``None``: any type).

    ``publishers`` maps each topic with live publishers to their announced types.
    """
    eager = eager_topics(table) if eager is None else eager
    wanted: dict[str, str | None] = {}
    for topic in sorted(set(publishers) | set(eager)):
        bounds = table.match(topic)
        if not bounds:
            continue
        declared = {b.ros_type for b in bounds if b.ros_type is not None}
        announced = set(publishers.get(topic, ()))
        if len(declared) == 1:
            wanted[topic] = next(iter(declared))
        elif declared:
            wanted[topic] = None
        else:
            wanted[topic] = next(iter(announced)) if len(announced) == 1 else None
    return wanted


@dataclass
class _Active:
    typename: str | None
    sub_id: int
    token: zenoh.LivelinessToken | None


class SubscriptionManager:
    """Keeps the node's subscriptions equal to ``plan(...)``. ``start()`` / ``stop()``."""

    def __init__(
        self,
        node: RosNode,
        table: MappingTable,
        source: NativeSource,
        *,
        known_type: Callable[[str], bool] | None = None,
    ) -> None:
        self.node = node
        self.table = table
        self.source = source
        self._known_type = known_type or _any_type
        self._publishers: dict[str, dict[str, str]] = {}  # topic -> token key -> type
        self._active: dict[str, _Active] = {}
        self._lock = threading.Lock()
        self._dirty = threading.Event()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._watcher: GraphWatcher | None = None
        self.generation = 0
        """Bumped after every reconciliation (tests and the admin API wait on it)."""
        self.errors = 0

    # -- lifecycle -------------------------------------------------------------------------------
    def start(self) -> SubscriptionManager:
        if self._thread is not None:
            return self
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="edge-subscriptions", daemon=True)
        self._thread.start()
        self._watcher = GraphWatcher(self.node.session, self.node.domain_id, listeners=(self._on_graph,))
        self._watcher.start()
        self.refresh()
        return self

    def stop(self) -> None:
        if self._watcher is not None:
            self._watcher.stop()
            self._watcher = None
        self._stop.set()
        self._dirty.set()
        if self._thread is not None:
            self._thread.join(10)
            self._thread = None
        with self._lock:
            active, self._active = self._active, {}
        for entry in active.values():
            self._close(entry)

    def __enter__(self) -> SubscriptionManager:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    def refresh(self) -> None:
        """Recompute the subscriptions soon (after the mapping table or the robots changed)."""
        self._dirty.set()

    # -- state -----------------------------------------------------------------------------------
    def topics(self) -> dict[str, str | None]:
        """Subscribed topic -> the type subscribed with."""
        with self._lock:
            return {topic: entry.typename for topic, entry in self._active.items()}

    def publishers(self) -> dict[str, list[str]]:
        with self._lock:
            return {topic: sorted(set(types.values())) for topic, types in self._publishers.items()}

    def snapshot(self) -> dict[str, dict[str, object]]:
        with self._lock:
            active = dict(self._active)
        return {
            topic: {"type": entry.typename, **self.source.subscription_stats(entry.sub_id)}
            for topic, entry in sorted(active.items())
        }

    # -- discovery -------------------------------------------------------------------------------
    def _on_graph(self, event: GraphEvent) -> None:
        entity = event.entity
        if not isinstance(entity, EndpointInfo) or entity.kind is not EntityKind.PUBLISHER:
            return
        with self._lock:
            per_topic = self._publishers.setdefault(entity.topic, {})
            if event.kind is EventKind.APPEARED:
                per_topic[entity.key] = entity.ros_type
            else:
                per_topic.pop(entity.key, None)
                if not per_topic:
                    del self._publishers[entity.topic]
        self._dirty.set()

    def _run(self) -> None:
        while not self._stop.is_set():
            self._dirty.wait()
            if self._stop.is_set():
                return
            self._dirty.clear()
            try:
                self._reconcile()
            except (RoswireError, SchemaError, MappingError, OSError) as exc:
                self.errors += 1
                log.warning("subscriptions: reconciliation failed (retrying): %s", exc)
                self._stop.wait(0.5)
                self._dirty.set()

    def _reconcile(self) -> None:
        with self._lock:
            publishers = {topic: set(types.values()) for topic, types in self._publishers.items()}
            current = {topic: entry.typename for topic, entry in self._active.items()}
        wanted = plan(publishers, self.table)
        for topic, typename in current.items():
            if wanted.get(topic, "\0") != typename:
                with self._lock:
                    entry = self._active.pop(topic)
                self._close(entry)
                log.info("unsubscribed %s", topic)
        for topic, typename in wanted.items():
            with self._lock:
                present = topic in self._active
            if present:
                continue
            active = self._open(topic, typename)
            with self._lock:
                self._active[topic] = active
            log.info("subscribed %s (type %s)", topic, typename or "any")
        self.generation += 1

    def _open(self, topic: str, typename: str | None) -> _Active:
        node = self.node
        # any type hash: a robot built against another revision of the type is still received
        sub_id = self.source.subscribe(topic, data_key_expr(node.domain_id, topic, typename, None))
        token: zenoh.LivelinessToken | None = None
        if typename is not None and self._known_type(typename):
            key = endpoint_token(
                domain=node.domain_id,
                zid=node.zid,
                nid=node.nid,
                eid=next_entity_id(),
                kind=EntityKind.SUBSCRIPTION,
                namespace=node.namespace,
                node_name=node.name,
                topic=topic,
                typename=typename,
                type_hash=node.type_hash(typename),
                qos=DEFAULT,
                enclave=node.enclave,
            )
            token = node.session.liveliness().declare_token(key)
        return _Active(typename, sub_id, token)

    def _close(self, entry: _Active) -> None:
        try:
            if entry.token is not None:
                entry.token.undeclare()
            self.source.unsubscribe(entry.sub_id)
        except Exception as exc:  # noqa: BLE001 - a closed session must not stop the rest of the cleanup
            log.debug("closing subscription %d failed: %r", entry.sub_id, exc)


def _any_type(_typename: str) -> bool:
    """Default ``known_type``: assume the node can hash every type."""
    return True
