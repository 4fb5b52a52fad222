"""Mapping declarations and their validation (config time, no I/O).

``MappingSpec`` is what a config file or the admin API declares; ``compile_mapping`` checks it
(pattern syntax, every template capture is captured by the pattern, static Kafka topic
legality, the ROS type's form) and returns a ``CompiledMapping`` ready for the table.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Literal, get_args

from fleetlink.common.names import (
    KAFKA_TOPIC_MAX,
    kafka_bad_chars,
    kafka_topic_problem,
    key_chunk_problem,
    ros_type_problem,
)
from fleetlink.edge.errors import MappingError
from fleetlink.edge.mapping.patterns import TopicPattern
from fleetlink.edge.mapping.templates import Template

Delivery = Literal["at_least_once", "best_effort"]
DELIVERIES: tuple[str, ...] = get_args(Delivery)


@dataclass(frozen=True, slots=True)
class MappingSpec:
    """One mapping as declared: ROS topic pattern -> Kafka topic template.

    ``key`` defaults to ``{robot}`` (the pattern must then capture ``robot``); ``ros_type``
    ``None`` means "discover it from the graph"; ``stages`` are the mapping's stage specs
    (``edge.stages`` objects), carried through untouched.
    """

    name: str
    source: str
    topic: str
    key: str | None = None
    ros_type: str | None = None
    delivery: Delivery = "at_least_once"
    stages: tuple[Any, ...] = ()
    linger_ns: int | None = None
    """How long the mapping's records may wait at the edge for company in a WAN batch
    (``None``: the edge's ``wan.linger``)."""
    claim_check: Any = None
    """``edge.claim_check.ClaimCheckSpec`` when large payloads go to the object store, carried
    through untouched like the stages."""


@dataclass(frozen=True, slots=True)
class RobotTypeSpec:
    """A robot type: robots whose namespace matches the glob ``match`` (``/tb4_*``) get
    ``mappings`` instantiated when they register."""

    name: str
    match: str
    mappings: tuple[MappingSpec, ...] = ()


@dataclass(frozen=True, slots=True)
class CompiledMapping:
    """A validated mapping (a site-level mapping, or a robot type's template)."""

    spec: MappingSpec
    robot_type: str | None
    pattern: TopicPattern
    topic: Template
    key: Template
    field_paths: tuple[tuple[str, ...], ...] = field(default=())

    @property
    def name(self) -> str:
        """The mapping's name."""
        return self.spec.name


def check_name(name: str, *, what: str = "mapping name") -> str:
    """``name`` if it is a valid key-expression chunk; raises ``MappingError`` otherwise."""
    problem = key_chunk_problem(name)
    if problem is not None:
        raise MappingError(f"{what} {name!r} {problem}")
    return name


def check_ros_type(ros_type: str, *, mapping: str | None = None) -> str:
    """``ros_type`` if it looks like ``package/msg/Type``; raises ``MappingError`` otherwise."""
    problem = ros_type_problem(ros_type)
    if problem is not None:
        raise MappingError(f"ROS type {ros_type!r} {problem}", mapping=mapping)
    return ros_type


def check_captures(template: Template, pattern: TopicPattern, what: str, mapping: str) -> None:
    """Raise ``MappingError`` when ``template`` uses a capture that ``pattern`` does not capture."""
    captured = set(pattern.captures)
    for name in sorted(template.captures - captured):
        have = ", ".join(pattern.captures) or "nothing"
        raise MappingError(
            f"{what} {template.text!r} uses {{{name}}}, which the pattern {pattern.text!r} does not "
            f"capture (it captures: {have}; message fields are written {{msg.field}})",
            mapping=mapping,
            template=template.text,
        )


def check_topic_literal(template: Template, mapping: str) -> None:
    """Raise ``MappingError`` when the Kafka topic ``template`` (its literal text, for a template) cannot
    make a legal Kafka topic name."""
    if template.is_literal:
        problem = kafka_topic_problem(template.literal_text)
        if problem:
            raise MappingError(
                f"Kafka topic {template.text!r}: {problem}", mapping=mapping, template=template.text
            )
        return
    literal = template.literal_text
    bad = kafka_bad_chars(literal)
    if bad:
        raise MappingError(
            f"Kafka topic template {template.text!r}: Kafka topic names use only [a-zA-Z0-9._-]; "
            f"{bad!r} is not allowed",
            mapping=mapping,
            template=template.text,
        )
    if len(literal) >= KAFKA_TOPIC_MAX:
        raise MappingError(
            f"Kafka topic template {template.text!r} is too long (max {KAFKA_TOPIC_MAX})",
            mapping=mapping,
            template=template.text,
        )


def compile_mapping(spec: MappingSpec, *, robot_type: str | None = None) -> CompiledMapping:
    """Validate ``spec``; raises ``MappingError`` naming the mapping and the faulty template."""
    name = spec.name
    check_name(name)
    if spec.delivery not in DELIVERIES:
        raise MappingError(f"delivery {spec.delivery!r} must be one of {', '.join(DELIVERIES)}", mapping=name)
    if spec.ros_type is not None:
        check_ros_type(spec.ros_type, mapping=name)
    if spec.linger_ns is not None and spec.linger_ns < 0:
        raise MappingError(f"linger {spec.linger_ns} ns must not be negative", mapping=name)
    pattern = TopicPattern.parse(spec.source, mapping=name)
    if robot_type is not None and not pattern.is_single("robot"):
        raise MappingError(
            f"topic pattern {spec.source!r}: mappings of robot type {robot_type!r} must capture the "
            "robot as one segment, e.g. '/{robot}/imu'",
            mapping=name,
            template=spec.source,
        )
    topic = Template.parse(spec.topic, mapping=name, what="Kafka topic template")
    check_captures(topic, pattern, "Kafka topic template", name)
    check_topic_literal(topic, name)
    if spec.key is None:
        if "robot" not in pattern.captures:
            raise MappingError(
                f"the key defaults to '{{robot}}' but the pattern {spec.source!r} captures no robot; "
                "set 'key' (a capture, a {msg.field} or fixed text)",
                mapping=name,
                template=spec.source,
            )
        key_text = "{robot}"
    else:
        key_text = spec.key
    key = Template.parse(key_text, mapping=name, what="key template")
    check_captures(key, pattern, "key template", name)
    paths = topic.field_paths + tuple(p for p in key.field_paths if p not in topic.field_paths)
    return CompiledMapping(
        spec=spec, robot_type=robot_type, pattern=pattern, topic=topic, key=key, field_paths=paths
    )


def check_unique_names(specs: Sequence[MappingSpec]) -> None:
    """Mapping names are unique across the whole edge (site-level and every robot type)."""
    seen: set[str] = set()
    for spec in specs:
        if spec.name in seen:
            raise MappingError(f"mapping name {spec.name!r} is used twice; names must be unique per edge")
        seen.add(spec.name)
