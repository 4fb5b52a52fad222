"""The live mapping table: which mappings a ROS topic feeds, as robots come and go.

Site-level mappings apply to every topic their pattern matches. A robot type's mappings are
templates: ``add_robot("tb4_01", "turtlebot4")`` instantiates each one with ``{robot}`` bound to
``tb4_01``; ``remove_robot`` takes them away. ``match(topic)`` returns every ``BoundMapping``
the topic feeds (one topic may feed several mappings, several topics one Kafka topic).

Thread-safety: changes are serialised by a lock and publish a new immutable snapshot; ``match``
reads the current snapshot without locking and caches its answer per topic (the cache belongs
to the snapshot, so any change invalidates it).
"""

from __future__ import annotations

import fnmatch
import threading
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from fleetlink.common.names import kafka_topic_problem
from fleetlink.edge.errors import MappingError, RenderError
from fleetlink.edge.mapping.patterns import TopicPattern, check_robot_name
from fleetlink.edge.mapping.spec import (
    CompiledMapping,
    Delivery,
    MappingSpec,
    RobotTypeSpec,
    check_unique_names,
    compile_mapping,
)
from fleetlink.edge.mapping.templates import Template


@dataclass(frozen=True, slots=True)
class BoundMapping:
    """One mapping applied to one concrete ROS topic (and robot).

    ``kafka_topic`` / ``key`` are set when they need no message field; otherwise call
    ``render_topic(fields)`` / ``render_key(fields)`` per record with the decoded message.
    """

    name: str
    robot: str | None
    robot_type: str | None
    source_topic: str
    ros_type: str | None
    delivery: Delivery
    stages: tuple[Any, ...]
    captures: Mapping[str, str]
    topic_template: Template
    key_template: Template
    kafka_topic: str | None
    key: str | None
    topic_error: str | None = None
    """Set when the topic is fully bound but illegal: every record is a ``RenderError``."""
    linger_s: float | None = None
    """How long this mapping's records may wait for company in a WAN batch (``None``: the
    stream's default)."""
    claim_check: Any = None
    """The mapping's ``ClaimCheckSpec``, when its large payloads go to the object store."""

    @property
    def needs_message_fields(self) -> bool:
        """Whether the Kafka topic or the key must be rendered from each record's message fields."""
        return not (self.topic_template.is_literal and self.key_template.is_literal)

    @property
    def field_paths(self) -> tuple[tuple[str, ...], ...]:
        """Message-field paths the topic and key templates read."""
        paths = self.topic_template.field_paths
        return paths + tuple(p for p in self.key_template.field_paths if p not in paths)

    def render_topic(self, fields: Mapping[str, Any] | None = None) -> str:
        """The Kafka topic for one record; raises ``RenderError`` (dead-letter it) when a field
        is missing or the result is not a legal Kafka topic name."""
        if self.kafka_topic is not None:
            return self.kafka_topic
        if self.topic_error is not None:
            raise RenderError(self.topic_error, mapping=self.name, template=self.topic_template.text)
        topic = self.topic_template.render(fields, mapping=self.name)
        problem = kafka_topic_problem(topic)
        if problem is not None:
            raise RenderError(
                f"rendered {topic!r}: {problem}",
                mapping=self.name,
                template=self.topic_template.text,
                value=topic,
            )
        return topic

    def render_key(self, fields: Mapping[str, Any] | None = None) -> str:
        """The record key (UTF-8 text) for one record; raises ``RenderError`` like ``render_topic``."""
        if self.key is not None:
            return self.key
        return self.key_template.render(fields, mapping=self.name)


@dataclass(frozen=True, slots=True)
class MappingInfo:
    """What ``MappingTable.list()`` reports for one mapping."""

    name: str
    robot_type: str | None
    source: str
    topic: str
    key: str
    ros_type: str | None
    delivery: Delivery
    robots: tuple[str, ...]
    """Robots this (robot-type) mapping is instantiated for; empty for site-level mappings."""
    stages: tuple[Any, ...]


@dataclass(frozen=True, slots=True)
class _Entry:
    compiled: CompiledMapping
    robot: str | None
    pattern: TopicPattern
    topic: Template
    key: Template


class _Snapshot:
    __slots__ = ("cache", "entries", "literal", "patterned")

    def __init__(self, entries: tuple[_Entry, ...]) -> None:
        self.entries = entries
        self.literal: dict[str, list[int]] = {}
        patterned: list[int] = []
        for index, entry in enumerate(entries):
            if entry.pattern.is_literal:
                self.literal.setdefault(entry.pattern.text, []).append(index)
            else:
                patterned.append(index)
        self.patterned = tuple(patterned)
        self.cache: dict[str, tuple[BoundMapping, ...]] = {}


def _bind(entry: _Entry, topic: str, captures: dict[str, str]) -> BoundMapping:
    compiled = entry.compiled
    robot = entry.robot if entry.robot is not None else captures.get("robot")
    if entry.robot is not None:
        captures = {"robot": entry.robot, **captures}
    topic_t = entry.topic.bind(captures, for_topic=True)
    key_t = entry.key.bind(captures)
    kafka_topic: str | None = None
    error: str | None = None
    if topic_t.is_literal:
        problem = kafka_topic_problem(topic_t.literal_text)
        if problem is None:
            kafka_topic = topic_t.literal_text
        else:
            error = f"rendered {topic_t.literal_text!r}: {problem}"
    return BoundMapping(
        name=compiled.name,
        robot=robot,
        robot_type=compiled.robot_type,
        source_topic=topic,
        ros_type=compiled.spec.ros_type,
        delivery=compiled.spec.delivery,
        stages=compiled.spec.stages,
        captures=captures,
        topic_template=topic_t,
        key_template=key_t,
        kafka_topic=kafka_topic,
        key=key_t.literal_text if key_t.is_literal else None,
        topic_error=error,
        linger_s=None if compiled.spec.linger_ns is None else compiled.spec.linger_ns / 1e9,
        claim_check=compiled.spec.claim_check,
    )


class MappingTable:
    """All mappings of one edge, site-level and per robot. See the module docstring."""

    def __init__(
        self,
        robot_types: Iterable[RobotTypeSpec] = (),
        mappings: Iterable[MappingSpec] = (),
        *,
        cache_size: int = 65536,
    ) -> None:
        self._lock = threading.Lock()
        self._cache_size = cache_size
        self._types: dict[str, RobotTypeSpec] = {}
        self._templates: dict[str, dict[str, CompiledMapping]] = {}
        self._site: dict[str, CompiledMapping] = {}
        self._robots: dict[str, str] = {}
        self._bound: dict[tuple[str, str], _Entry] = {}
        self.version = 0
        self._install(tuple(robot_types), tuple(mappings))
        self._snapshot = self._build()

    # -- configuration -------------------------------------------------------------------------
    def _install(self, robot_types: tuple[RobotTypeSpec, ...], mappings: tuple[MappingSpec, ...]) -> None:
        """Validate everything first, then replace the declarations (all or nothing)."""
        names = [t.name for t in robot_types]
        for name in names:
            if names.count(name) > 1:
                raise MappingError(f"robot type {name!r} is declared twice")
        check_unique_names([*mappings, *(m for t in robot_types for m in t.mappings)])
        site = {m.name: self._compiled(m, None, self._site.get(m.name)) for m in mappings}
        templates = {
            t.name: {
                m.name: self._compiled(m, t.name, self._templates.get(t.name, {}).get(m.name))
                for m in t.mappings
            }
            for t in robot_types
        }
        self._types = {t.name: t for t in robot_types}
        self._templates = templates
        self._site = site

    @staticmethod
    def _compiled(spec: MappingSpec, robot_type: str | None, old: CompiledMapping | None) -> CompiledMapping:
        """The mapping compiled; an unchanged one keeps its old object, so the runtime keeps its
        stage objects (and their state and counters) across a reload of the others."""
        if old is not None and old.robot_type == robot_type and old.spec == spec:
            return old
        return compile_mapping(spec, robot_type=robot_type)

    def reload(
        self, robot_types: Iterable[RobotTypeSpec], mappings: Iterable[MappingSpec]
    ) -> tuple[str, ...]:
        """Replace every declaration (config reload). Registered robots keep their type when it
        still exists; returns the robots removed because their type is gone."""
        with self._lock:
            self._install(tuple(robot_types), tuple(mappings))
            gone = tuple(r for r, t in self._robots.items() if t not in self._types)
            for robot in gone:
                del self._robots[robot]
            self._publish()
            return gone

    def _all_names(self) -> set[str]:
        return set(self._site) | {n for t in self._templates.values() for n in t}

    def add_mapping(self, spec: MappingSpec, robot_type: str | None = None) -> None:
        """Add a site-level mapping, or a template to ``robot_type`` (instantiated at once for
        every registered robot of that type). Raises ``MappingError`` if invalid or the name is taken."""
        with self._lock:
            if spec.name in self._all_names():
                raise MappingError("a mapping with this name exists already", mapping=spec.name)
            if robot_type is None:
                self._site[spec.name] = compile_mapping(spec)
            else:
                if robot_type not in self._types:
                    raise MappingError(f"unknown robot type {robot_type!r}", mapping=spec.name)
                self._templates[robot_type][spec.name] = compile_mapping(spec, robot_type=robot_type)
            self._publish()

    def remove_mapping(self, name: str) -> bool:
        """Remove a mapping (site-level or robot-type template) by name; False if unknown."""
        with self._lock:
            if self._site.pop(name, None) is None:
                owner = next((t for t, ms in self._templates.items() if name in ms), None)
                if owner is None:
                    return False
                del self._templates[owner][name]
            self._publish()
            return True

    # -- robots ----------------------------------------------------------------------------------
    def robot_globs(self) -> dict[str, str]:
        """Robot type -> the ``match`` glob of its robots' namespaces (``/tb4_*``)."""
        with self._lock:
            return {
                name: spec.match if spec.match.startswith("/") else "/" + spec.match
                for name, spec in self._types.items()
            }

    def robot_type_for(self, robot: str) -> str | None:
        """The first robot type (declaration order) whose ``match`` glob matches the namespace."""
        namespace = "/" + robot.strip("/")
        for spec in self._types.values():
            glob = spec.match if spec.match.startswith("/") else "/" + spec.match
            if fnmatch.fnmatchcase(namespace, glob):
                return spec.name
        return None

    def awaits_robot(self, topic: str) -> bool:
        """Whether a robot type's mapping would take ``topic`` once its robot registers: the topic
        matches one of the type's source patterns, the captured robot matches that type's
        ``match`` glob first, and that robot is not registered yet."""
        with self._lock:
            for kind, templates in self._templates.items():
                for compiled in templates.values():
                    captures = compiled.pattern.match(topic)
                    robot = None if captures is None else captures.get("robot")
                    if robot and robot not in self._robots and self.robot_type_for(robot) == kind:
                        return True
            return False

    def add_robot(self, robot: str, robot_type: str | None = None) -> tuple[str, ...]:
        """Register a robot (its type from ``robot_type`` or else from the ``match`` globs) and
        instantiate its type's mappings; returns their names. Re-registering is idempotent."""
        name = check_robot_name(robot)
        with self._lock:
            kind = robot_type if robot_type is not None else self.robot_type_for(name)
            if kind is None:
                raise MappingError(f"robot {name!r} matches no robot type's 'match' glob")
            if kind not in self._types:
                raise MappingError(f"robot {name!r}: unknown robot type {kind!r}")
            if self._robots.get(name) != kind:
                self._robots[name] = kind
                self._publish()
            return tuple(self._templates[kind])

    def remove_robot(self, robot: str) -> bool:
        """Deregister a robot and drop its mappings; False if it was not registered."""
        with self._lock:
            if self._robots.pop(robot.strip("/"), None) is None:
                return False
            self._publish()
            return True

    def robots(self) -> dict[str, str]:
        """Registered robots -> their type."""
        with self._lock:
            return dict(self._robots)

    # -- queries ---------------------------------------------------------------------------------
    def list(self) -> list[MappingInfo]:
        """Every mapping, site-level first, then each robot type's, in declaration order."""
        with self._lock:
            out = [self._info(m, ()) for m in self._site.values()]
            for kind, templates in self._templates.items():
                robots = tuple(r for r, t in self._robots.items() if t == kind)
                out.extend(self._info(m, robots) for m in templates.values())
            return out

    @staticmethod
    def _info(compiled: CompiledMapping, robots: tuple[str, ...]) -> MappingInfo:
        spec = compiled.spec
        return MappingInfo(
            name=spec.name,
            robot_type=compiled.robot_type,
            source=spec.source,
            topic=spec.topic,
            key=compiled.key.text,
            ros_type=spec.ros_type,
            delivery=spec.delivery,
            robots=robots,
            stages=spec.stages,
        )

    def match(self, topic: str) -> tuple[BoundMapping, ...]:
        """Every mapping ``topic`` feeds, in declaration order (empty tuple: none)."""
        snapshot = self._snapshot
        hit = snapshot.cache.get(topic)
        if hit is not None:
            return hit
        indices = list(snapshot.literal.get(topic, ()))
        found: dict[int, dict[str, str]] = {i: {} for i in indices}
        for index in snapshot.patterned:
            captures = snapshot.entries[index].pattern.match(topic)
            if captures is not None:
                found[index] = captures
        result = tuple(_bind(snapshot.entries[i], topic, found[i]) for i in sorted(found))
        if len(snapshot.cache) >= self._cache_size:
            snapshot.cache.clear()
        snapshot.cache[topic] = result
        return result

    # -- snapshots -------------------------------------------------------------------------------
    def _build(self) -> _Snapshot:
        entries: list[_Entry] = [
            _Entry(compiled=m, robot=None, pattern=m.pattern, topic=m.topic, key=m.key)
            for m in self._site.values()
        ]
        reused: dict[tuple[str, str], _Entry] = {}
        for robot, kind in self._robots.items():
            for m in self._templates[kind].values():
                entry = self._bound.get((robot, m.name))
                if entry is None or entry.compiled is not m:
                    bound = {"robot": robot}
                    entry = _Entry(
                        compiled=m,
                        robot=robot,
                        pattern=m.pattern.bind(bound),
                        topic=m.topic.bind(bound, for_topic=True),
                        key=m.key.bind(bound),
                    )
                reused[(robot, m.name)] = entry
                entries.append(entry)
        self._bound = reused
        return _Snapshot(tuple(entries))

    def _publish(self) -> None:
        self._snapshot = self._build()
        self.version += 1
