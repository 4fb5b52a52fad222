"""Command mappings: a Kafka topic -> a ROS topic per robot, with a repeat period and a lease.

::

    commands:
      - name: lightring                       # one key chunk: fleetlink/<site>/command/<robot>/lightring
        from: fleet.commands.lightring        # Kafka topic (records: Avro, Confluent wire format)
        to: "/{key}/cmd_lightring"            # ROS topic template
        type: irobot_create_msgs/msg/LightringLeds
        repeat: {period: 1s, lease: 10s}
      - name: task
        from: fleet.tasks
        to: "/{msg.robot_id}/task"            # robot from a field of the record
        type: my_msgs/msg/Task
      - name: all_lights
        from: fleet.commands.all
        to: "/{robot}/cmd_lightring"
        type: irobot_create_msgs/msg/LightringLeds
        broadcast: true                       # every registered robot, at every site

Placeholders: ``{key}`` (the record key, UTF-8), ``{msg.a.b}`` (a field of the decoded
record: a string or an integer), ``{robot}`` (the target robot). **Which robot** a record
addresses: ``robot:`` (``"{key}"`` or ``"{msg.path}"``) when given; otherwise the placeholder
that forms the first segment of ``to`` (``/{key}/…`` → the key, ``/{msg.robot_id}/…`` → that
field); otherwise the key. With ``broadcast: true`` every registered robot is addressed, and
``to`` must contain ``{robot}``.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Literal

from pydantic import ConfigDict, Field, field_validator, model_validator

from fleetlink.common.configfile import Section
from fleetlink.common.durations import PositiveSeconds
from fleetlink.common.names import KafkaTopic, KeyChunk, RosType, key_path_problem
from fleetlink.roswire.errors import InvalidNameError
from fleetlink.roswire.names import validate_topic
from fleetlink.roswire.qos import Durability, QoS, Reliability
from fleetlink.uplink.commands.errors import RoutingError

_PLACEHOLDER = re.compile(r"\{([^{}]*)\}")
_FIELD_PATH = re.compile(r"msg(?:\.[A-Za-z_][A-Za-z0-9_]*)+")


# -- templates ------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Ref:
    """A placeholder: ``key``, ``robot`` or ``msg`` with a field path."""

    kind: Literal["key", "robot", "msg"]
    path: tuple[str, ...] = ()

    @property
    def text(self) -> str:
        """The placeholder as written in a template, braces included (``{msg.robot_id}``)."""
        return "{" + ".".join((self.kind, *self.path)) + "}"


@dataclass(frozen=True, slots=True)
class Template:
    """A name template (``to``, ``robot``) split into literal text and placeholders."""

    text: str
    parts: tuple[str | Ref, ...]

    @property
    def refs(self) -> tuple[Ref, ...]:
        """The template's placeholders, in order."""
        return tuple(p for p in self.parts if isinstance(p, Ref))

    def sample(self, value: str = "r1") -> str:
        """The template with every placeholder filled with ``value`` (to validate it)."""
        return "".join(p if isinstance(p, str) else value for p in self.parts)

    def render(self, *, key: str | None, robot: str | None, record: Mapping[str, Any] | None) -> str:
        """The template with every placeholder filled in; ``RoutingError`` when one cannot be."""
        out: list[str] = []
        for part in self.parts:
            out.append(part if isinstance(part, str) else resolve(part, key=key, robot=robot, record=record))
        return "".join(out)


def parse_template(text: str) -> Template:
    """Split ``text`` into literals and placeholders; raise ``ValueError`` for unknown ones."""
    parts: list[str | Ref] = []
    pos = 0
    for match in _PLACEHOLDER.finditer(text):
        literal = text[pos : match.start()]
        if "{" in literal or "}" in literal:
            raise ValueError(f"unbalanced brace in {text!r}")
        if literal:
            parts.append(literal)
        name = match.group(1).strip()
        if name in ("key", "robot"):
            parts.append(Ref(name))  # type: ignore[arg-type]
        elif _FIELD_PATH.fullmatch(name):
            parts.append(Ref("msg", tuple(name.split(".")[1:])))
        else:
            raise ValueError(
                f"unknown placeholder {{{name}}} in {text!r}: use {{key}}, {{robot}} or {{msg.<field>}}"
            )
        pos = match.end()
    tail = text[pos:]
    if "{" in tail or "}" in tail:
        raise ValueError(f"unbalanced brace in {text!r}")
    if tail:
        parts.append(tail)
    return Template(text, tuple(parts))


def resolve(ref: Ref, *, key: str | None, robot: str | None, record: Mapping[str, Any] | None) -> str:
    """What ``ref`` stands for: the record key, the target robot, or a string or integer field of the
    record; ``RoutingError`` when it is missing or of another type."""
    if ref.kind == "key":
        if not key:
            raise RoutingError("the record has no key, but the mapping needs {key}")
        return key
    if ref.kind == "robot":
        if not robot:
            raise RoutingError("no robot to fill {robot} with")
        return robot
    value: Any = record
    for name in ref.path:
        if not isinstance(value, Mapping) or name not in value:
            raise RoutingError(f"the record has no field {'.'.join(ref.path)} (for {ref.text})")
        value = value[name]
    if isinstance(value, bool) or not isinstance(value, str | int):
        raise RoutingError(
            f"field {'.'.join(ref.path)} is a {type(value).__name__}, "
            f"not a string or an integer (for {ref.text})"
        )
    return str(value)


# -- config model ---------------------------------------------------------------------------


class RepeatSection(Section):
    """How often the repeater publishes a command, and for how long."""

    model_config = ConfigDict(frozen=True)

    period: PositiveSeconds = 1.0
    """How often the repeater publishes the command while its lease holds."""
    lease: PositiveSeconds = 10.0
    """How long the command is valid, from its Kafka record's timestamp."""


class CommandQoS(Section):
    """The QoS of the repeater's publisher on the robot's ROS topic."""

    model_config = ConfigDict(frozen=True)

    reliability: Literal["reliable", "best_effort"] = "reliable"
    durability: Literal["volatile", "transient_local"] = "volatile"
    depth: int = Field(default=10, ge=1, le=10_000)

    def to_keyexpr(self) -> str:
        """The QoS as rmw_zenoh's compact string."""
        return QoS(
            reliability=Reliability.RELIABLE if self.reliability == "reliable" else Reliability.BEST_EFFORT,
            durability=Durability.VOLATILE if self.durability == "volatile" else Durability.TRANSIENT_LOCAL,
            depth=self.depth,
        ).to_keyexpr()


def check_ros_template(value: str, what: str, *, robot_only: bool = False) -> str:
    """``value`` if it is an absolute ROS name template whose sample is a valid ``what``
    (with ``robot_only``, one that refers to ``{robot}`` at most), else a ValueError."""
    template = parse_template(value)
    if not value.startswith("/"):
        raise ValueError(f"{value!r} must be an absolute {what} (start with '/')")
    if robot_only and any(ref.kind != "robot" for ref in template.refs):
        raise ValueError(f"{value!r} may use {{robot}} only (the robot comes from 'robot')")
    sample = template.sample()
    try:
        validate_topic(sample)
    except InvalidNameError as exc:
        raise ValueError(f"{value!r} makes no valid {what} ({sample!r}: {exc.reason})") from None
    return value


def check_robot_template(value: str) -> str:
    """``value`` if it is exactly one ``{key}`` or ``{msg.<field>}`` reference, else a ValueError."""
    refs = parse_template(value).refs
    if len(refs) != 1 or value.strip() != refs[0].text or refs[0].kind == "robot":
        raise ValueError(f'robot {value!r} must be exactly one of "{{key}}" or "{{msg.<field>}}"')
    return value


class CommandMapping(Section):
    """One Kafka topic -> one ROS topic per addressed robot."""

    model_config = ConfigDict(populate_by_name=True, frozen=True)

    name: KeyChunk
    from_: KafkaTopic = Field(alias="from")
    to: str
    type: RosType
    robot: str | None = None
    broadcast: bool = False
    repeat: RepeatSection = RepeatSection()
    qos: CommandQoS | None = None

    @field_validator("to")
    @classmethod
    def _to(cls, value: str) -> str:
        return check_ros_template(value, "ROS topic")

    @field_validator("robot")
    @classmethod
    def _robot(cls, value: str | None) -> str | None:
        return None if value is None else check_robot_template(value)

    @model_validator(mode="after")
    def _targets(self) -> CommandMapping:
        refs = parse_template(self.to).refs
        if self.broadcast:
            if self.robot is not None:
                raise ValueError("broadcast: true addresses every registered robot; drop 'robot'")
            if Ref("robot") not in refs:
                raise ValueError("broadcast: true needs {robot} in 'to'")
        if self.repeat.period > self.repeat.lease:
            raise ValueError(
                f"repeat.period ({self.repeat.period} s) is longer than repeat.lease "
                f"({self.repeat.lease} s): the command would be published once"
            )
        return self

    # -- derived --------------------------------------------------------------------------

    @property
    def to_template(self) -> Template:
        """``to`` parsed into literals and placeholders."""
        return parse_template(self.to)

    @property
    def robot_ref(self) -> Ref | None:
        """Where the robot comes from (None: broadcast)."""
        if self.broadcast:
            return None
        if self.robot is not None:
            return parse_template(self.robot).refs[0]
        first = self.to.split("/")[1] if self.to.count("/") >= 1 else ""
        parts = parse_template(first).parts if first else ()
        if len(parts) == 1 and isinstance(parts[0], Ref) and parts[0].kind != "robot":
            return parts[0]
        return Ref("key")

    @property
    def qos_text(self) -> str | None:
        """The publisher QoS as rmw_zenoh's compact string (None: reliable, volatile, depth 10)."""
        return None if self.qos is None else self.qos.to_keyexpr()

    @property
    def period_ms(self) -> int:
        """``repeat.period`` in whole milliseconds (at least 1)."""
        return max(1, round(self.repeat.period * 1000))

    @property
    def lease_ms(self) -> int:
        """``repeat.lease`` in whole milliseconds (at least 1)."""
        return max(1, round(self.repeat.lease * 1000))


@dataclass(frozen=True, slots=True)
class Target:
    """A robot a record addresses and the ROS topic its command goes to."""

    robot: str
    ros_topic: str


def targets(
    mapping: CommandMapping, *, key: str | None, record: Mapping[str, Any], known_robots: Iterable[str] = ()
) -> list[Target]:
    """The (robot, ROS topic) pairs a decoded record addresses; ``RoutingError`` when none can be."""
    template = mapping.to_template
    ref = mapping.robot_ref
    robots = sorted(set(known_robots)) if ref is None else [resolve(ref, key=key, robot=None, record=record)]
    out: list[Target] = []
    for robot in robots:
        problem = key_path_problem(robot)
        if problem is not None:
            raise RoutingError(f"robot {robot!r} {problem}")
        topic = template.render(key=key, robot=robot, record=record)
        try:
            validate_topic(topic)
        except InvalidNameError as exc:
            raise RoutingError(f"robot {robot!r}: {topic!r} is no valid ROS topic ({exc.reason})") from None
        out.append(Target(robot, topic))
    return out


def unique_names(mappings: list[CommandMapping]) -> list[CommandMapping]:
    """Raise ``ValueError`` when two mappings share a name (it is part of the command's key)."""
    seen: set[str] = set()
    for mapping in mappings:
        if mapping.name in seen:
            raise ValueError(f"two command mappings are named {mapping.name!r}")
        seen.add(mapping.name)
    return mappings
