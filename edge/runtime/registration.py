"""Robot registration: the registry's events -> a Kafka record and a ROS message each.

A ``RobotWatcher`` keeps the registry current (robots discovered in the graph by their
namespace, with a grace period before a vanished robot is deregistered). Robots may also
register explicitly with a ``std_msgs/msg/String`` ``"<robot_type>/<robot_name>"`` on the
configured topic (``/fleetlink/register``). Every registration and deregistration becomes:

* an Avro record (``EVENT_SCHEMA``) on the registrations topic, keyed by robot, so a compacted
  topic holds each robot's latest state; it goes through the durable spool like any record;
* a ``std_msgs/msg/String`` with the same content as JSON on ``/fleetlink/robots`` (kept for
  late joiners: transient local, last 100).
"""

from __future__ import annotations

import json
import logging
import threading
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from types import TracebackType
from typing import Any

from fleetlink.edge.runtime.encoding import AvroWriter
from fleetlink.edge.runtime.records import H_EDGE, H_ROBOT, H_SITE
from fleetlink.roswire import cdr
from fleetlink.roswire.errors import RobotError
from fleetlink.roswire.node import RosNode
from fleetlink.roswire.publisher import RosPublisher
from fleetlink.roswire.qos import DEFAULT, Durability, QoS
from fleetlink.roswire.robot_watcher import STRING_HASHES, STRING_TYPE, RobotWatcher
from fleetlink.roswire.robots import Reason, RobotEvent, RobotEventKind, RobotType, parse_registration
from fleetlink.roswire.subscriber import RosSample, RosSubscriber
from fleetlink.wire import Record, single_object
from fleetlink.wire.robot_events import EVENT_SCHEMA

log = logging.getLogger(__name__)

ROBOTS_TOPIC = "/fleetlink/robots"
_WRITER = AvroWriter(EVENT_SCHEMA)
EVENT_FINGERPRINT = _WRITER.fingerprint
EVENT_SCHEMA_JSON = _WRITER.identity.json


@dataclass(frozen=True, slots=True)
class RobotChange:
    """One registration or deregistration, as the edge reports it."""

    robot: str
    robot_type: str
    registered: bool
    reason: str
    timestamp_ms: int

    @property
    def event(self) -> str:
        """``registered`` or ``deregistered``."""
        return "registered" if self.registered else "deregistered"

    @classmethod
    def from_event(cls, event: RobotEvent, timestamp_ms: int) -> RobotChange:
        """The change a registry event reports, stamped with ``timestamp_ms`` (wall-clock milliseconds)."""
        return cls(
            event.robot,
            event.robot_type,
            event.kind is RobotEventKind.REGISTERED,
            event.reason.value,
            timestamp_ms,
        )


def event_datum(change: RobotChange, site: str, edge_id: str) -> dict[str, Any]:
    """The ``EVENT_SCHEMA`` datum of ``change`` at this site and edge."""
    return {
        "robot": change.robot,
        "robot_type": change.robot_type,
        "site": site,
        "edge_id": edge_id,
        "event": change.event,
        "reason": change.reason,
        "timestamp": change.timestamp_ms,
    }


def event_record(change: RobotChange, *, site: str, edge_id: str, topic: str) -> Record:
    """The Kafka record of one change (key = robot)."""
    body = _WRITER.body(event_datum(change, site, edge_id))
    return Record(
        kafka_topic=topic,
        key=change.robot.encode(),
        value=single_object(EVENT_FINGERPRINT, body),
        headers=((H_SITE, site.encode()), (H_ROBOT, change.robot.encode()), (H_EDGE, edge_id.encode())),
        timestamp_ms=change.timestamp_ms,
    )


def event_json(change: RobotChange, *, site: str, edge_id: str) -> str:
    """The JSON text published on ``/fleetlink/robots``."""
    return json.dumps(event_datum(change, site, edge_id), separators=(",", ":"))


Listener = Callable[[RobotChange], object]


class Registrar:
    """Runs the robot watcher and the explicit-registration subscriber; reports each change
    once to ``listener`` (from a watcher or Zenoh thread: the listener must not block)."""

    def __init__(
        self,
        node: RosNode,
        types: Iterable[RobotType],
        listener: Listener,
        *,
        site: str,
        edge_id: str,
        grace_s: float,
        discover: bool = True,
        register_topic: str = "/fleetlink/register",
        clock_ms: Callable[[], int],
    ) -> None:
        self.node = node
        self.types = tuple(types)
        self.listener = listener
        self.site = site
        self.edge_id = edge_id
        self.discover = discover
        self.register_topic = register_topic
        self._clock_ms = clock_ms
        self._watcher = RobotWatcher(node, self.types, grace_s=grace_s, listeners=(self._on_event,))
        self._registered: dict[str, str] = {}
        self._lock = threading.Lock()
        self._publisher: RosPublisher | None = None
        self._subscriber: RosSubscriber | None = None
        self.bad_registrations = 0
        self.events = 0

    def start(self) -> Registrar:
        """Declare the robots publisher and the explicit-registration subscriber, then start the robot
        watcher; returns ``self``."""
        distro_hash = STRING_HASHES.get(self.node.distro)
        self._publisher = self.node.create_publisher(
            ROBOTS_TOPIC,
            STRING_TYPE,
            QoS(durability=Durability.TRANSIENT_LOCAL, depth=100),
            type_hash=distro_hash,
        )
        self._subscriber = self.node.create_subscriber(
            self.register_topic, STRING_TYPE, self._on_registration, DEFAULT, type_hash=distro_hash
        )
        self._watcher.start()
        return self

    def prime(self, timeout_s: float = 2.0) -> int:
        """Register the robots alive now before returning (what ``start`` finds asynchronously)."""
        return self._watcher.prime(timeout_s)

    def stop(self) -> None:
        """Stop the robot watcher and undeclare the publisher and subscriber; cleanup errors are logged."""
        self._watcher.stop()
        for entity in (self._subscriber, self._publisher):
            if entity is not None:
                try:
                    entity.stop()
                except Exception as exc:  # noqa: BLE001 - a closed session must not stop the cleanup
                    log.debug("registration cleanup: %r", exc)
        self._subscriber = None
        self._publisher = None

    def __enter__(self) -> Registrar:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    def robots(self) -> dict[str, str]:
        """The robots registered now: robot name -> robot type."""
        with self._lock:
            return dict(self._registered)

    def register(self, robot_type: str, name: str) -> None:
        """Explicit registration (also what the register topic does)."""
        self._watcher.register(robot_type, name)
        with self._lock:  # the registry already knew it (discovered) but discovery is off
            missing = name not in self._registered
        if missing:
            self._changed(RobotChange(name, robot_type, True, Reason.EXPLICIT.value, self._clock_ms()))

    # -- callbacks -------------------------------------------------------------------------------
    def _on_registration(self, sample: RosSample) -> None:
        try:
            robot_type, name = parse_registration(cdr.decode_string(sample.payload))
            self.register(robot_type, name)
        except (ValueError, RobotError) as exc:
            self.bad_registrations += 1
            log.warning("ignoring a registration on %s: %s", self.register_topic, exc)

    def _on_event(self, event: RobotEvent) -> None:
        discovered = event.kind is RobotEventKind.REGISTERED and event.reason is Reason.DISCOVERED
        if discovered and not self.discover:
            return
        self._changed(RobotChange.from_event(event, self._clock_ms()))

    def _changed(self, change: RobotChange) -> None:
        with self._lock:
            known = self._registered.get(change.robot)
            if change.registered:
                if known is not None:
                    return
                self._registered[change.robot] = change.robot_type
            else:
                if known is None:
                    return
                del self._registered[change.robot]
            self.events += 1
        log.info("robot %s %s (type %s, %s)", change.robot, change.event, change.robot_type, change.reason)
        self.listener(change)
        publisher = self._publisher
        if publisher is not None:
            try:
                publisher.publish_cdr(
                    cdr.encode_string(event_json(change, site=self.site, edge_id=self.edge_id))
                )
            except Exception as exc:  # noqa: BLE001 - the ROS copy is informative; the Kafka one counts
                log.warning("cannot publish on %s: %r", ROBOTS_TOPIC, exc)
