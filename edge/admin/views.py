"""Response shapes of the admin API (documented in the OpenAPI document)."""

from __future__ import annotations

from typing import Any, Literal

from pydantic import BaseModel, ConfigDict, Field


class _View(BaseModel):
    model_config = ConfigDict(populate_by_name=True)


class ProblemView(_View):
    """One problem with a request."""

    path: str = Field(description="where in the request body, e.g. 'stages[1].hz' ('<root>': the body)")
    message: str
    config_path: str | None = Field(
        default=None,
        description="the same place in the effective edge config, e.g. 'mappings[3].stages[1].hz'",
    )


class ErrorView(_View):
    """An error answer: the HTTP status, a message and the problems found."""

    status: int
    error: str
    problems: list[ProblemView] = []


class MappingCountersView(_View):
    """A mapping's running totals of records."""

    received: int = 0
    emitted: int = 0
    dropped: int = 0
    dead_lettered: int = 0
    type_mismatch: int = 0


class StageView(_View):
    """One stage of a mapping with its running totals."""

    name: str
    type: str
    received: int = 0
    passed: int = 0
    dropped: int = 0
    late: int = 0
    errors: int = 0
    emitted: int = 0


class IssueView(_View):
    """Something the runtime found wrong with a mapping (it keeps running, degraded)."""

    reason: str
    detail: str


class MappingView(_View):
    """A mapping as declared, with where it came from, its robots and its counters."""

    name: str
    robot_type: str | None = Field(description="the robot type whose template this is; null: site-level")
    origin: Literal["config", "admin"] = Field(
        description="from the config file, or added/changed at runtime"
    )
    source: str = Field(alias="from")
    to: str
    key: str | None
    type: str | None
    delivery: str
    stages: list[dict[str, Any]] = Field(description="the stage list as in the config file")
    robots: list[str] = Field(description="robots this robot-type mapping is instantiated for")
    counters: MappingCountersView
    stage_counters: list[StageView]
    issues: list[IssueView] = []


class RobotEventView(_View):
    """One registration or deregistration of a robot at this edge."""

    event: Literal["registered", "deregistered"]
    robot_type: str
    reason: str = Field(description="discovered, explicit or liveliness_lost")
    at: float = Field(description="seconds since the epoch")


class RobotView(_View):
    """A robot known to the edge: its robot type, state and registration history."""

    robot: str
    robot_type: str
    registered_at: float | None = Field(description="seconds since the epoch; null when not known")
    registered_since: str | None = Field(description="the same as ISO 8601 UTC text")
    state: Literal["registered", "lost"]
    explicit: bool = Field(description="registered on the register topic rather than discovered")
    history: list[RobotEventView] = Field(
        default=[], description="its last registrations and deregistrations at this edge, oldest first"
    )


class PublisherView(_View):
    """A node that publishes a topic, with the type it publishes."""

    node: str
    type: str
    type_hash: str


class TopicMatchView(_View):
    """A mapping that takes a topic, with the Kafka topic and key it writes."""

    mapping: str
    robot: str | None
    kafka_topic: str = Field(description="the Kafka topic, or its template when it reads message fields")
    key: str


class TopicView(_View):
    """A discovered ROS topic: its types, publishers, subscriber count and matching mappings."""

    topic: str
    types: list[str]
    publishers: list[PublisherView]
    subscribers: int
    mappings: list[TopicMatchView]


class RobotTypeView(_View):
    """A robot type: its namespace glob, mappings, registered robots and origin."""

    name: str
    match: str
    mappings: list[str]
    robots: list[str]
    origin: Literal["config", "admin"]


class DryRunMatchView(_View):
    """A discovered topic the dry-run mapping would match."""

    topic: str
    types: list[str]
    robot: str | None
    registered: bool = Field(description="false: the robot is in the graph but not registered (yet)")
    kafka_topic: str
    key: str
    type_ok: bool = Field(
        description="false: the topic's type differs from the mapping's 'type' (not mapped)"
    )


class DryRunView(_View):
    """What a mapping would match now, without changing anything."""

    mapping: str
    robot_type: str | None
    matches: list[DryRunMatchView]


class ChangeView(_View):
    """The result of a change: what was created, changed or removed and where it was saved."""

    status: Literal["created", "changed", "removed"]
    kind: Literal["mapping", "robot_type"]
    name: str
    overlay: str | None = Field(description="the file the change was saved to (null: not persisted)")


class DamageView(_View):
    """One damage finding of the durable spool (docs/spool.md, "Damage")."""

    reason: str = Field(description="corrupt, truncated, segment_missing, ledger_missing or torn_tail")
    file: str = Field(description="the file's name in the spool directory")
    offset: int
    end: int
    first_seq: int | None = Field(default=None, description="the first seq lost (null: none or not known)")
    last_seq: int | None = None
    records: int = Field(description="records lost (not acknowledged by Kafka when found)")
    detail: str
    found_ms: int
    acknowledged_ms: int | None = Field(default=None, description="null: awaiting an operator")


class DamageAckView(_View):
    """The spool damage findings an acknowledgement cleared."""

    acknowledged: list[DamageView] = Field(description="the findings that awaited an acknowledgement")
