"""``GraphWatcher``: live ROS graph from rmw_zenoh liveliness tokens (rmw_zenoh.md §3).

Declares a liveliness subscriber on ``@ros2_lv/<domain>/**`` with history, so tokens that
existed before the watcher started are reported too, and feeds every PUT/DELETE into a pure
:class:`~roswire.graph.Graph`. Malformed tokens are counted (``stats.malformed``) and skipped.
Listeners get each :class:`~roswire.graph.GraphEvent` in order, on a zenoh thread.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass
from types import TracebackType

import zenoh

from fleetlink.roswire.errors import TokenError
from fleetlink.roswire.graph import Graph, GraphEvent, TopicInfo
from fleetlink.roswire.tokens import EndpointInfo, NodeInfo, liveliness_prefix

log = logging.getLogger(__name__)

GraphListener = Callable[[GraphEvent], object]


@dataclass
class WatcherStats:
    """Liveliness token changes seen by a watcher, malformed tokens and listener failures."""

    puts: int = 0
    deletes: int = 0
    malformed: int = 0
    listener_errors: int = 0
    last_malformed: str = ""


class GraphWatcher:
    """Keeps a :class:`Graph` current from a domain's liveliness tokens and tells listeners of each change."""

    def __init__(
        self,
        session: zenoh.Session,
        domain_id: int = 0,
        *,
        ignore_own: bool = True,
        listeners: tuple[GraphListener, ...] = (),
    ) -> None:
        self.session = session
        self.domain_id = domain_id
        self.ignore_own = ignore_own
        self.stats = WatcherStats()
        self._listeners = list(listeners)
        self._lock = threading.RLock()
        self._graph = Graph(domain=domain_id)
        self._sub: zenoh.Subscriber[None] | None = None

    def add_listener(self, listener: GraphListener) -> None:
        """Also hand every later graph event to ``listener`` (called on a zenoh thread)."""
        with self._lock:
            self._listeners.append(listener)

    def start(self) -> GraphWatcher:
        """Declare the liveliness subscriber (with history) on the domain's tokens; returns self."""
        if self._sub is not None:
            return self
        if self.ignore_own:
            self._graph.own_zid = str(self.session.zid())
        self._sub = self.session.liveliness().declare_subscriber(
            liveliness_prefix(self.domain_id), self._on_token, history=True
        )
        return self

    def prime(self, timeout_s: float = 2.0) -> int:
        """Ask for every token alive now and apply the answers before returning (the history of
        ``start``'s subscriber arrives a little later, asynchronously; what it repeats changes
        nothing). Returns the tokens received."""
        replies = self.session.liveliness().get(liveliness_prefix(self.domain_id), timeout=timeout_s)
        count = 0
        for reply in replies:
            if reply.ok is not None:
                self._on_token(reply.ok)
                count += 1
        return count

    def stop(self) -> None:
        """Undeclare the liveliness subscriber; the graph keeps its last state."""
        if self._sub is not None:
            self._sub.undeclare()
            self._sub = None

    def __enter__(self) -> GraphWatcher:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    def _on_token(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        with self._lock:
            try:
                if sample.kind == zenoh.SampleKind.DELETE:
                    self.stats.deletes += 1
                    events = self._graph.delete(key)
                else:
                    self.stats.puts += 1
                    events = self._graph.put(key)
            except TokenError as exc:
                self.stats.malformed += 1
                self.stats.last_malformed = key
                level = logging.WARNING if self.stats.malformed == 1 else logging.DEBUG
                log.log(
                    level, "ignoring malformed liveliness token (%d so far): %s", self.stats.malformed, exc
                )
                return
            for event in events:
                for listener in self._listeners:
                    try:
                        listener(event)
                    except Exception as exc:  # noqa: BLE001 - a bad listener must not stop discovery
                        self.stats.listener_errors += 1
                        log.warning("graph listener failed on %s: %r", event.kind.value, exc)

    # --- thread-safe queries -----------------------------------------------------------------

    def nodes(self) -> list[NodeInfo]:
        """Every node known now, sorted by fully qualified name."""
        with self._lock:
            return self._graph.nodes()

    def endpoints(self) -> list[EndpointInfo]:
        """Every endpoint known now, sorted by topic, kind and id."""
        with self._lock:
            return self._graph.endpoints()

    def topics(self) -> dict[str, TopicInfo]:
        """Topic name -> types, publishers and subscribers known now."""
        with self._lock:
            return self._graph.topics()

    def services(self) -> dict[str, TopicInfo]:
        """Service name -> types, servers and clients known now."""
        with self._lock:
            return self._graph.services()

    def __len__(self) -> int:
        with self._lock:
            return len(self._graph)
