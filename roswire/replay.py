"""Replay a rosbag2 recording (sqlite3 or MCAP) onto Zenoh as robot NAME would publish it.

Every topic is prefixed with ``/NAME`` (``/imu/data`` -> ``/tb4_01/imu/data``) and published by
one :class:`~roswire.node.RosNode` in namespace ``/NAME`` with the exact keys, tokens, hashes and
attachments of rmw_zenoh. Timing follows the recording scaled by ``rate`` (``rate=2`` plays twice
as fast); ``rate=0`` publishes as fast as the network accepts (publishers then block instead of
dropping, so nothing is lost). The bag's CDR records go out byte for byte.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any

import zenoh

from fleetlink.roswire.errors import BagError
from fleetlink.roswire.names import join_namespace, validate_node_name, validate_topic
from fleetlink.roswire.node import RosNode
from fleetlink.roswire.publisher import Congestion, RosPublisher
from fleetlink.roswire.qos import DEFAULT, Durability, History, QoS, Reliability
from fleetlink.schemas.typestore import Distro, load_typestore

log = logging.getLogger(__name__)


def robot_topic(robot: str, topic: str) -> str:
    """``("tb4_01", "/imu/data")`` -> ``/tb4_01/imu/data``."""
    return validate_topic(join_namespace(f"/{validate_node_name(robot)}", topic.strip("/")))


def qos_from_bag(profiles: Sequence[Any]) -> QoS:
    """The QoS to publish with, from a bag's ``offered_qos_profiles`` (first profile; default if none).

    Values a publisher cannot offer (history UNKNOWN, depth 0) fall back to rclcpp's defaults.
    """
    if not profiles:
        return DEFAULT
    prof = profiles[0]

    def num(value: Any) -> int:  # rosbags uses plain Enums for the policies
        return int(getattr(value, "value", value))

    reliability = (
        Reliability.BEST_EFFORT
        if num(prof.reliability) == Reliability.BEST_EFFORT
        else (Reliability.RELIABLE)
    )
    durability = (
        Durability.TRANSIENT_LOCAL
        if num(prof.durability) == Durability.TRANSIENT_LOCAL
        else (Durability.VOLATILE)
    )
    history = History.KEEP_ALL if num(prof.history) == History.KEEP_ALL else History.KEEP_LAST
    depth = num(prof.depth) if num(prof.depth) > 0 else DEFAULT.depth
    return QoS(reliability=reliability, durability=durability, history=history, depth=depth)


@dataclass(frozen=True)
class ReplaySchedule:
    """When (monotonic seconds) a recorded message is due: recorded offset divided by ``rate``."""

    first_ns: int
    start: float
    rate: float

    def due(self, timestamp_ns: int) -> float:
        """The monotonic time the message recorded at ``timestamp_ns`` goes out (the start with rate 0)."""
        if self.rate <= 0:
            return self.start
        return self.start + (timestamp_ns - self.first_ns) / 1e9 / self.rate


@dataclass
class ReplayStats:
    """What a replay has done: messages published per topic, loops played, worst lateness, duration."""

    published: Counter[str] = field(default_factory=Counter)
    loops: int = 0
    max_lateness_s: float = 0.0
    elapsed_s: float = 0.0

    @property
    def total(self) -> int:
        """Messages published across all topics."""
        return sum(self.published.values())


class BagReplayer:
    """Replays a rosbag2 recording onto Zenoh as the publishers of one robot's namespace."""

    def __init__(
        self,
        bag: Path,
        robot: str,
        *,
        config: zenoh.Config | None = None,
        session: zenoh.Session | None = None,
        domain_id: int = 0,
        distro: Distro = "jazzy",
        msg_paths: Sequence[Path] = (),
        rate: float = 1.0,
        loop: bool = False,
        topics: Sequence[str] | None = None,
        node_name: str = "replay",
        clock: Callable[[], float] = time.monotonic,
        congestion: Congestion | None = None,
    ) -> None:
        """``congestion``: what a publisher does when the way is full (``None``: block at ``rate``
        0, else as rmw_zenoh does for the topic's recorded QoS, which drops for KEEP_LAST)."""
        if rate < 0:
            raise BagError(f"replay rate must be >= 0 (0 = as fast as possible), got {rate}")
        self.bag = Path(bag)
        self.robot = validate_node_name(robot)
        self.rate = rate
        self.loop = loop
        self.topics = set(topics) if topics is not None else None
        self.distro: Distro = distro
        self.msg_paths = tuple(msg_paths)
        self.clock = clock
        self.congestion = congestion
        self.stats = ReplayStats()
        self._node_args: dict[str, Any] = {
            "namespace": f"/{robot}",
            "domain_id": domain_id,
            "config": config,
            "session": session,
        }
        self._node_name = node_name
        self.node: RosNode | None = None
        self.publishers: dict[str, RosPublisher] = {}
        self._reader: Any = None
        self._connections: list[Any] = []
        self._stop = threading.Event()

    def start(self) -> BagReplayer:
        """Open the bag, start the node and create one publisher per selected topic; returns self.

        Raises :class:`BagError` when the bag is missing, unreadable, has none of the topics, or stores
        something other than CDR.
        """
        if self.node is not None:
            return self
        from rosbags.rosbag2 import Reader, ReaderError

        if not self.bag.exists():
            raise BagError(f"bag not found: {self.bag}")
        typestore = load_typestore(self.distro, self.msg_paths, [self.bag])
        try:
            self._reader = Reader(self.bag)
            self._reader.open()
        except ReaderError as exc:
            raise BagError(f"cannot open bag {self.bag}: {exc}") from exc
        connections = [c for c in self._reader.connections if self.topics is None or c.topic in self.topics]
        if not connections:
            raise BagError(f"bag {self.bag} has none of the requested topics {sorted(self.topics or [])}")
        for conn in connections:
            fmt = getattr(conn.ext, "serialization_format", "cdr")
            if fmt != "cdr":
                raise BagError(f"{self.bag}: topic {conn.topic} is stored as {fmt!r}, not cdr")
        self.node = RosNode(
            self._node_name, typestore=typestore, distro=self.distro, **self._node_args
        ).start()
        congestion = self.congestion or ("block" if self.rate == 0 else None)
        for conn in connections:
            if conn.topic in self.publishers:
                continue
            qos = qos_from_bag(getattr(conn.ext, "offered_qos_profiles", []))
            self.publishers[conn.topic] = self.node.create_publisher(
                robot_topic(self.robot, conn.topic), conn.msgtype, qos, congestion=congestion
            )
        self._connections = connections
        return self

    def stop(self) -> None:
        """Stop a running :meth:`run`, the node with its publishers, and close the bag."""
        self._stop.set()
        if self.node is not None:
            self.node.stop()
            self.node = None
        if self._reader is not None:
            self._reader.close()
            self._reader = None
        self.publishers = {}

    def __enter__(self) -> BagReplayer:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    def wait_for_subscribers(self, timeout: float) -> bool:
        """Wait until every topic has a subscriber (useful before a fast replay); False on timeout."""
        deadline = self.clock() + timeout
        pending = list(self.publishers.values())
        while pending:
            pending = [p for p in pending if not p.has_subscribers()]
            if not pending:
                break
            if self.clock() >= deadline or self._stop.wait(0.05):
                return False
        return True

    def request_stop(self) -> None:
        """Make :meth:`run` return after the message in flight (thread-safe)."""
        self._stop.set()

    def run(self) -> ReplayStats:
        """Publish the bag (again and again with ``loop``) until done or :meth:`request_stop`."""
        if self.node is None:
            raise BagError("replayer is not started")
        began = self.clock()
        while not self._stop.is_set():
            self._play_once()
            self.stats.loops += 1
            if not self.loop:
                break
        self.stats.elapsed_s = self.clock() - began
        return self.stats

    def _play_once(self) -> None:
        schedule: ReplaySchedule | None = None
        for conn, timestamp, raw in self._reader.messages(connections=self._connections):
            if schedule is None:
                schedule = ReplaySchedule(timestamp, self.clock(), self.rate)
            wait = schedule.due(timestamp) - self.clock()
            if wait > 0:
                if self._stop.wait(wait):
                    return
            elif self.rate > 0:
                self.stats.max_lateness_s = max(self.stats.max_lateness_s, -wait)
            if self._stop.is_set():
                return
            self.publishers[conn.topic].publish_cdr(bytes(raw))
            self.stats.published[conn.topic] += 1
