"""``RobotWatcher``: the robot registry kept current from a live graph.

Wires a :class:`~roswire.discovery.GraphWatcher` into a pure
:class:`~roswire.robots.RobotRegistry`, runs its grace-period clock on a small timer thread,
(optionally) listens for explicit registrations on ``/fleetlink/register``
(``std_msgs/msg/String`` ``"<robot_type>/<robot_name>"``) and (optionally) publishes every
registration and deregistration as JSON in a ``std_msgs/msg/String`` on ``/fleetlink/robot_events``::

    {"event": "registered", "robot": "tb4_07", "robot_type": "turtlebot4", "reason": "discovered"}
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections.abc import Callable, Iterable
from types import TracebackType

from fleetlink.roswire import cdr
from fleetlink.roswire.discovery import GraphWatcher
from fleetlink.roswire.errors import RobotError
from fleetlink.roswire.graph import GraphEvent
from fleetlink.roswire.names import HASH_NOT_SUPPORTED
from fleetlink.roswire.node import RosNode
from fleetlink.roswire.publisher import RosPublisher
from fleetlink.roswire.robots import Robot, RobotEvent, RobotRegistry, RobotType, parse_registration
from fleetlink.roswire.subscriber import RosSample, RosSubscriber

log = logging.getLogger(__name__)

REGISTER_TOPIC = "/fleetlink/register"
EVENTS_TOPIC = "/fleetlink/robot_events"
STRING_TYPE = "std_msgs/msg/String"
STRING_HASHES = {
    "humble": HASH_NOT_SUPPORTED,
    "jazzy": "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
    "kilted": "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
}

RobotListener = Callable[[RobotEvent], object]


def event_json(event: RobotEvent) -> str:
    """The JSON text published on the events topic for one registry event."""
    return json.dumps(
        {
            "event": event.kind.value,
            "robot": event.robot,
            "robot_type": event.robot_type,
            "reason": event.reason.value,
        }
    )


class RobotWatcher:
    """Keeps a :class:`RobotRegistry` current from a node's live graph; thread-safe."""

    def __init__(
        self,
        node: RosNode,
        types: Iterable[RobotType],
        *,
        grace_s: float = 5.0,
        tick_s: float = 0.1,
        listeners: tuple[RobotListener, ...] = (),
        registrations: bool = False,
        events_topic: str | None = None,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.node = node
        self.registry = RobotRegistry(types, grace_s)
        self.tick_s = tick_s
        self.clock = clock
        self.registrations = registrations
        self.events_topic = events_topic
        self._events_pub: RosPublisher | None = None
        self.bad_registrations = 0
        self._listeners = list(listeners)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.watcher: GraphWatcher | None = None
        self._register_sub: RosSubscriber | None = None

    def add_listener(self, listener: RobotListener) -> None:
        """Also hand every later registration and deregistration to ``listener``."""
        self._listeners.append(listener)

    def start(self) -> RobotWatcher:
        """Start the node, events publisher, graph watcher, registrations and grace timer; returns self."""
        if self.watcher is not None:
            return self
        self.node.start()
        self._stop.clear()
        if self.events_topic is not None:
            self._events_pub = self.node.create_publisher(
                self.events_topic, STRING_TYPE, type_hash=STRING_HASHES.get(self.node.distro)
            )
        self.watcher = GraphWatcher(self.node.session, self.node.domain_id, listeners=(self._on_graph,))
        self.watcher.start()
        if self.registrations:
            self._register_sub = self.node.create_subscriber(
                REGISTER_TOPIC,
                STRING_TYPE,
                self._on_registration,
                type_hash=STRING_HASHES.get(self.node.distro),
            )
        self._thread = threading.Thread(target=self._run, name="robot-watcher", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop the timer, registration subscriber, events publisher and graph watcher (not the node)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=5)
            self._thread = None
        if self._register_sub is not None:
            self._register_sub.stop()
            self._register_sub = None
        if self._events_pub is not None:
            self._events_pub.stop()
            self._events_pub = None
        if self.watcher is not None:
            self.watcher.stop()
            self.watcher = None

    def __enter__(self) -> RobotWatcher:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    def prime(self, timeout_s: float = 2.0) -> int:
        """Register the robots whose tokens are alive now before returning (``GraphWatcher.prime``)."""
        return 0 if self.watcher is None else self.watcher.prime(timeout_s)

    def robots(self) -> list[Robot]:
        """Copies of every registered robot, sorted by name."""
        with self._lock:
            return self.registry.robots()

    def register(self, robot_type: str, name: str) -> None:
        """Register a robot by hand and emit the event; raises :class:`RobotError` on a bad type or name."""
        with self._lock:
            events = self.registry.register(robot_type, name, self.clock())
        self._emit(events)

    def _on_graph(self, event: GraphEvent) -> None:
        with self._lock:
            events = self.registry.on_graph_event(event, self.clock())
        self._emit(events)

    def _on_registration(self, sample: RosSample) -> None:
        try:
            robot_type, name = parse_registration(cdr.decode_string(sample.payload))
            self.register(robot_type, name)
        except (ValueError, RobotError) as exc:
            self.bad_registrations += 1
            log.warning("ignoring registration on %s: %s", REGISTER_TOPIC, exc)

    def _run(self) -> None:
        while not self._stop.wait(self.tick_s):
            with self._lock:
                events = self.registry.tick(self.clock())
            self._emit(events)

    def _emit(self, events: list[RobotEvent]) -> None:
        for event in events:
            log.info(
                "robot %s %s type=%s reason=%s",
                event.robot,
                event.kind.value,
                event.robot_type,
                event.reason.value,
            )
            if self._events_pub is not None:
                self._events_pub.publish_cdr(cdr.encode_string(event_json(event)))
            for listener in self._listeners:
                try:
                    listener(event)
                except Exception as exc:  # noqa: BLE001 - a bad listener must not stop the registry
                    log.warning("robot listener failed: %r", exc)
