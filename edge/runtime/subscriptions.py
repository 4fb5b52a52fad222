"""What the edge receives: a few wildcard key expressions for the data, a token per mapped topic.

A ``GraphWatcher`` reports every publisher (``MP`` token) with its topic and type. Whenever the
graph or the mapping table changes, the wanted subscriptions are recomputed (``plan``, pure)
and the difference applied on a small thread of its own (never on a Zenoh callback thread):
new topics are subscribed, topics no mapping wants any more are dropped. A topic is subscribed
with the type a mapping declares, else the type its publishers announce (any type, ``*``, when
they disagree), and always with any type hash (``*``): a robot built against a slightly
different definition is still received, and the hash each sample really carried goes into its
record's headers. A mapping that declares its type subscribes as soon as its topic is known
(a robot registered), before any publisher shows up.

The data arrives through the edge's native data plane (``dataplane.NativeSource``), on one key
expression per mapping source pattern (``receive_keys``): ``/{robot}/imu`` of robot type
``/tb4_*`` is received as ``<domain>/tb4_$*/imu/<type>/*``, so the receive path costs the same for
ten robots or a thousand (a Zenoh session matches each sample against all of its subscriptions:
a thousand exact ones cost some 50 µs a sample more than one wildcard). What arrives for a robot
or topic no mapping takes is recognised once per data key and then dropped natively. The topics
that do feed a mapping (``plan``) get a subscription liveliness token (``MS``, so that ``ros2
topic info`` counts the edge), declared on the edge's Python session as its node is.
"""

from __future__ import annotations

import fnmatch
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
from fleetlink.roswire.names import dds_type_name
from fleetlink.roswire.node import RosNode
from fleetlink.roswire.qos import DEFAULT
from fleetlink.roswire.tokens import EndpointInfo, EntityKind
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


def _chunk_of_glob(glob_segment: str) -> str:
    """A Zenoh key chunk matching (at least) the names an fnmatch segment matches."""
    if glob_segment == "*" or any(c in glob_segment for c in "?[]"):
        return "*"
    return glob_segment.replace("*", "$*")


def _chunks(pattern: TopicPattern, robot_chunk: str | None) -> list[str]:
    out = []
    for segment in pattern.segments:
        if isinstance(segment, str):
            out.append(segment)
        elif segment.name == "robot" and robot_chunk is not None:
            out.append(robot_chunk)
        else:
            out.append("**" if segment.multi else "*")
    return out


def receive_keys(table: MappingTable, domain: int) -> set[str]:
    """The key expressions that receive every topic a mapping of ``table`` may take: per mapping,
    its source pattern with captures as wildcards (a robot type's ``{robot}`` as its ``match``
    glob), the declared type or any, any hash; plus exact keys for registered robots that do
    not match their type's glob (registered explicitly)."""
    globs = table.robot_globs()
    keys: set[str] = set()
    for info in table.list():
        pattern = TopicPattern.parse(info.source)
        dds = dds_type_name(info.ros_type) if info.ros_type is not None else "*"
        patterns: list[tuple[TopicPattern, str | None]] = [(pattern, None)]
        if info.robot_type is not None:
            glob = globs.get(info.robot_type, "/*")
            patterns = [(pattern, _chunk_of_glob(glob.strip("/")))]
            for robot in info.robots:
                if not fnmatch.fnmatchcase("/" + robot.strip("/"), glob):
                    patterns.append((pattern.bind({"robot": robot.strip("/")}), None))
        for bound, robot_chunk in patterns:
            key = f"{domain}/{'/'.join(_chunks(bound, robot_chunk))}/{dds}/*"
            keys.add(str(zenoh.KeyExpr.autocanonize(key)))
    return keys


@dataclass
class _Active:
    """A topic that feeds a mapping: the type it is taken as, and its subscription token."""

    typename: str | None
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
        self._receivers: dict[str, int] = {}  # key expression -> data plane subscription
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
        """Start the worker thread and the graph watcher, then compute the subscriptions once; returns
        ``self``."""
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
        """Stop the graph watcher and the worker thread, then close every subscription."""
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
            receivers, self._receivers = self._receivers, {}
        for entry in active.values():
            self._close(entry)
        for sub_id in receivers.values():
            self._unreceive(sub_id)

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
    def receivers(self) -> list[str]:
        """The key expressions the data plane receives on."""
        with self._lock:
            return sorted(self._receivers)

    def topics(self) -> dict[str, str | None]:
        """Topic feeding a mapping -> the type it is taken as (``None``: any)."""
        with self._lock:
            return {topic: entry.typename for topic, entry in self._active.items()}

    def publishers(self) -> dict[str, list[str]]:
        """The ROS types announced per topic by the publishers seen in the graph."""
        with self._lock:
            return {topic: sorted(set(types.values())) for topic, types in self._publishers.items()}

    def snapshot(self) -> dict[str, dict[str, object]]:
        """Per topic feeding a mapping (and any other that sent something): its type and counters."""
        with self._lock:
            types = {topic: entry.typename for topic, entry in self._active.items()}
        stats = self.source.topic_stats()
        empty = dict.fromkeys(
            (
                "received",
                "delivered",
                "rejected",
                "unmapped",
                "waiting",
                "gaps",
                "missing",
                "duplicates",
                "lost_at_restart",
            ),
            0,
        )
        return {
            topic: {"type": types.get(topic), **stats.get(topic, empty)}
            for topic in sorted(set(types) | set(stats))
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
            except (RoswireError, SchemaError, MappingError, OSError, RuntimeError, zenoh.ZError) as exc:
                self.errors += 1
                log.warning("subscriptions: reconciliation failed (retrying): %s", exc)
                self._stop.wait(0.5)
                self._dirty.set()

    def _reconcile(self) -> None:
        with self._lock:
            publishers = {topic: set(types.values()) for topic, types in self._publishers.items()}
            current = {topic: entry.typename for topic, entry in self._active.items()}
            receiving = set(self._receivers)
        keys = receive_keys(self.table, self.node.domain_id)
        for key in sorted(receiving - keys):
            with self._lock:
                sub_id = self._receivers.pop(key)
            self._unreceive(sub_id)
            log.info("stopped receiving %s", key)
        for key in sorted(keys - receiving):
            sub_id = self.source.subscribe(key)
            with self._lock:
                self._receivers[key] = sub_id
            log.info("receiving %s", key)
        wanted = plan(publishers, self.table)
        for topic, typename in current.items():
            if wanted.get(topic, "\0") != typename:
                with self._lock:
                    entry = self._active.pop(topic)
                self._close(entry)
                log.debug("unsubscribed %s", topic)
        for topic, typename in wanted.items():
            with self._lock:
                present = topic in self._active
            if present:
                continue
            active = self._open(topic, typename)
            with self._lock:
                self._active[topic] = active
            log.debug("subscribed %s (type %s)", topic, typename or "any")
        self.generation += 1

    def _open(self, topic: str, typename: str | None) -> _Active:
        node = self.node
        token: zenoh.LivelinessToken | None = None
        if typename is not None and self._known_type(typename):
            key = node.endpoint_token(
                EntityKind.SUBSCRIPTION, topic, typename, type_hash=node.type_hash(typename), qos=DEFAULT
            )
            token = node.session.liveliness().declare_token(key)
        return _Active(typename, token)

    def _close(self, entry: _Active) -> None:
        try:
            if entry.token is not None:
                entry.token.undeclare()
        except zenoh.ZError as exc:  # a closed session must not stop the rest of the cleanup
            log.debug("undeclaring a subscription token failed: %s", exc)

    def _unreceive(self, sub_id: int) -> None:
        try:
            self.source.unsubscribe(sub_id)
        except RuntimeError as exc:  # a closed data plane must not stop the rest of the cleanup
            log.debug("closing receiver %d failed: %s", sub_id, exc)


def _any_type(_typename: str) -> bool:
    """Default ``known_type``: assume the node can hash every type."""
    return True
