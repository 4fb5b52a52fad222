"""The robot registry: which robots exist, from graph events and explicit registrations.

Pure state with an injected clock (``now`` in seconds). A robot is the first segment of a
namespace matching one of the configured robot-type patterns (``/tb4_*`` makes the nodes of
``/tb4_07`` and ``/tb4_07/sensors`` robot ``tb4_07``). A robot is registered with its first
entity (or explicitly, even before it is discovered) and deregistered once its last entity has
been gone for the grace period (:meth:`RobotRegistry.tick`).
"""

from __future__ import annotations

import fnmatch
from collections.abc import Iterable
from dataclasses import dataclass, field
from enum import Enum

from fleetlink.common.names import ROS_SEGMENT
from fleetlink.roswire.errors import RobotError
from fleetlink.roswire.graph import EventKind, GraphEvent
from fleetlink.roswire.names import first_segment


class RobotEventKind(Enum):
    """Whether a robot joined or left the registry."""

    REGISTERED = "registered"
    DEREGISTERED = "deregistered"


class Reason(Enum):
    """Why a robot was registered or deregistered."""

    DISCOVERED = "discovered"
    EXPLICIT = "explicit"
    LIVELINESS_LOST = "liveliness_lost"


@dataclass(frozen=True)
class RobotType:
    """A robot type and the namespace pattern of its robots, e.g. ``RobotType("turtlebot4", "/tb4_*")``."""

    name: str
    match: str

    def __post_init__(self) -> None:
        if not self.match.startswith("/") or "/" in self.match[1:] or len(self.match) < 2:
            raise RobotError(
                f"robot type {self.name!r}: pattern {self.match!r} must be one namespace "
                "segment such as '/tb4_*'"
            )

    def matches(self, segment: str) -> bool:
        """Whether the namespace segment ``segment`` (without its ``/``) fits this type's pattern."""
        return fnmatch.fnmatchcase("/" + segment, self.match)


@dataclass(frozen=True)
class RobotEvent:
    """A robot registered or deregistered, why, and when (clock seconds)."""

    kind: RobotEventKind
    robot: str
    robot_type: str
    reason: Reason
    at: float


@dataclass
class Robot:
    """A registered robot: its type, when it was registered, and the token keys of its live entities.

    ``empty_since`` is when its last entity disappeared; None while it has entities (or never had any).
    """

    name: str
    robot_type: str
    registered_at: float
    explicit: bool
    entities: set[str] = field(default_factory=set)
    empty_since: float | None = None

    @property
    def namespace(self) -> str:
        """The robot's namespace, ``/<name>``."""
        return f"/{self.name}"


def parse_registration(text: str) -> tuple[str, str]:
    """``"turtlebot4/tb4_07"`` (the ``/fleetlink/register`` message) -> ``("turtlebot4", "tb4_07")``."""
    robot_type, sep, name = text.strip().partition("/")
    if not sep or not robot_type or not ROS_SEGMENT.fullmatch(name):
        raise RobotError(f"registration {text!r}: expected '<robot_type>/<robot_name>'")
    return robot_type, name


class RobotRegistry:
    """Which robots exist, from graph events and explicit registrations; not thread-safe."""

    def __init__(self, types: Iterable[RobotType], grace_s: float = 5.0) -> None:
        self.types = tuple(types)
        if grace_s < 0:
            raise RobotError(f"grace period must be >= 0, got {grace_s}")
        self.grace_s = grace_s
        self._robots: dict[str, Robot] = {}
        self._type_names = {t.name for t in self.types}

    def classify(self, namespace: str) -> tuple[str, str] | None:
        """The (robot name, robot type) a namespace belongs to, or None."""
        segment = first_segment(namespace)
        if segment is None:
            return None
        known = self._robots.get(segment)
        if known is not None:
            return segment, known.robot_type
        for robot_type in self.types:
            if robot_type.matches(segment):
                return segment, robot_type.name
        return None

    def on_graph_event(self, event: GraphEvent, now: float) -> list[RobotEvent]:
        """Update the robot a node or endpoint belongs to; the registration it caused, if any.

        A disappearing entity never deregisters at once: :meth:`tick` does after the grace period.
        """
        found = self.classify(event.entity.namespace)
        if found is None:
            return []
        name, robot_type = found
        key = event.entity.key
        if event.kind is EventKind.APPEARED:
            robot = self._robots.get(name)
            events: list[RobotEvent] = []
            if robot is None:
                robot = Robot(name, robot_type, now, explicit=False)
                self._robots[name] = robot
                events.append(RobotEvent(RobotEventKind.REGISTERED, name, robot_type, Reason.DISCOVERED, now))
            robot.entities.add(key)
            robot.empty_since = None
            return events
        robot = self._robots.get(name)
        if robot is not None and key in robot.entities:
            robot.entities.discard(key)
            if not robot.entities:
                robot.empty_since = now
        return []

    def register(self, robot_type: str, name: str, now: float) -> list[RobotEvent]:
        """Explicit registration; a robot already known keeps its entities (no new event)."""
        if robot_type not in self._type_names:
            raise RobotError(f"unknown robot type {robot_type!r} (known: {sorted(self._type_names)})")
        if not ROS_SEGMENT.fullmatch(name):
            raise RobotError(f"robot name {name!r} is not a single namespace segment")
        robot = self._robots.get(name)
        if robot is not None:
            robot.explicit = True
            return []
        self._robots[name] = Robot(name, robot_type, now, explicit=True)
        return [RobotEvent(RobotEventKind.REGISTERED, name, robot_type, Reason.EXPLICIT, now)]

    def deregister(self, name: str, now: float) -> list[RobotEvent]:
        """Remove a robot at once, whatever its entities; the event, or none for an unknown robot."""
        robot = self._robots.pop(name, None)
        if robot is None:
            return []
        return [RobotEvent(RobotEventKind.DEREGISTERED, name, robot.robot_type, Reason.EXPLICIT, now)]

    def tick(self, now: float) -> list[RobotEvent]:
        """Deregister robots whose last entity disappeared at least ``grace_s`` ago."""
        gone = [
            r
            for r in self._robots.values()
            if r.empty_since is not None and now - r.empty_since >= self.grace_s
        ]
        for robot in gone:
            del self._robots[robot.name]
        return [
            RobotEvent(RobotEventKind.DEREGISTERED, r.name, r.robot_type, Reason.LIVELINESS_LOST, now)
            for r in sorted(gone, key=lambda r: r.name)
        ]

    def robots(self) -> list[Robot]:
        """Copies of every registered robot, sorted by name."""
        return [
            Robot(r.name, r.robot_type, r.registered_at, r.explicit, set(r.entities), r.empty_since)
            for r in sorted(self._robots.values(), key=lambda r: r.name)
        ]

    def get(self, name: str) -> Robot | None:
        """The registered robot called ``name`` (the live record, not a copy), or None."""
        return self._robots.get(name)

    def __contains__(self, name: object) -> bool:
        return name in self._robots

    def __len__(self) -> int:
        return len(self._robots)
