"""The edge agent's one config model (``fleetlink edge run -c edge.yaml``).

Load it with ``fleetlink.common.configfile.load_config(EdgeConfig, path)``: every problem is reported
with its YAML path (``robot_types.turtlebot4.mappings[1].to (line 14): ...``) and no socket
is opened. Durations are text with a unit (``250ms``, ``5s``) or seconds, held as nanoseconds;
sizes are bytes or text (``64MiB``, ``1GiB``). See deploy/edge.example.yaml.
"""

from __future__ import annotations

import socket
from pathlib import Path
from typing import Literal

from pydantic import (
    ByteSize,
    ConfigDict,
    Field,
    ValidationInfo,
    field_validator,
    model_validator,
)

from fleetlink.common.configfile import Section
from fleetlink.common.names import KafkaTopic, KeyChunk, NamespaceGlob, RosTopic, RosType, Site, host_id
from fleetlink.common.objects import ObjectStoreSection
from fleetlink.common.zenoh_options import ZenohSection
from fleetlink.edge.claim_check import ClaimCheckSpec
from fleetlink.edge.errors import EdgeError, MappingError
from fleetlink.edge.mapping import (
    Delivery,
    MappingSpec,
    MappingTable,
    RobotTypeSpec,
    Template,
    TopicPattern,
)
from fleetlink.edge.mapping.spec import check_captures, check_topic_literal
from fleetlink.edge.spool import FsyncPolicy, FullPolicy, MemoryBuffer, SpoolOptions
from fleetlink.edge.stages import AggregateSpec, DurationNs, StageSpec
from fleetlink.wire import Codec

_NS = 1_000_000_000


def _why(exc: EdgeError) -> str:
    """The reason without the 'mapping X:' prefix (the YAML path already says where)."""
    return str(exc).split(": ", 1)[1] if str(exc).startswith("mapping ") else str(exc)


def default_edge_id() -> str:
    """The host name, cut to a valid key-expression chunk."""
    return host_id(socket.gethostname(), "edge")


class RosSection(Section):
    """The ROS side: domain id, distro, extra message packages and the rmw_zenoh attachment version."""

    domain_id: int = Field(default=0, ge=0, le=232)
    distro: Literal["humble", "iron", "jazzy", "kilted", "rolling"] = "jazzy"
    """Decides type hashes and the rmw_zenoh wire details."""
    message_paths: list[Path] = []
    """Folders of your own packages (each holding ``msg/``, ``srv/``, ``action/``); the standard
    ones and irobot_create_msgs ship with fleetlink (a folder here replaces a package of its name)."""
    attachment: Literal["auto", "v1", "v2"] = "auto"


class MappingConfig(Section):
    """One mapping: ROS topic pattern ``from`` -> Kafka topic template ``to``."""

    model_config = ConfigDict(populate_by_name=True)

    name: KeyChunk
    from_: str = Field(alias="from")
    to: str
    key: str | None = Field(default=None, validate_default=True)
    type: RosType | None = None
    delivery: Delivery = "at_least_once"
    stages: list[StageSpec] = []
    linger: DurationNs | None = None
    """How long this mapping's records may wait at the edge for others to share their WAN batch.
    Default: ``wan.linger``; with an ``aggregate`` stage, the stage's hop (its window when
    tumbling), at most 5s: window records are few, and each batch costs a query and an answer."""
    claim_check: ClaimCheckSpec | None = None
    """Large payloads go to the edge's object store (``objects``), the record carries a reference
    (docs/images.md)."""

    @field_validator("linger")
    @classmethod
    def _linger(cls, value: int | None) -> int | None:
        if value is not None and not 0 <= value <= MAX_LINGER_NS:
            raise ValueError("linger must be between 0s and 60s")
        return value

    @field_validator("from_")
    @classmethod
    def _pattern(cls, value: str) -> str:
        try:
            TopicPattern.parse(value)
        except MappingError as exc:
            raise ValueError(_why(exc)) from None
        return value

    @field_validator("to")
    @classmethod
    def _topic(cls, value: str, info: ValidationInfo) -> str:
        return _check_template(value, info, "Kafka topic template", topic=True)

    @field_validator("key")
    @classmethod
    def _key(cls, value: str | None, info: ValidationInfo) -> str | None:
        source = info.data.get("from_")
        if value is None:
            if source is not None and "robot" not in TopicPattern.parse(source).captures:
                raise ValueError(
                    f"the key defaults to '{{robot}}' but 'from' ({source!r}) captures no "
                    "robot; set a key (a capture, a {msg.field} or fixed text)"
                )
            return None
        return _check_template(value, info, "key template", topic=False)

    def spec(self) -> MappingSpec:
        """This mapping as a ``MappingSpec``; without a ``linger``, an aggregate stage's hop or window (at
        most 5s) is used, else ``None`` (``wan.linger``)."""
        return MappingSpec(
            name=self.name,
            source=self.from_,
            topic=self.to,
            key=self.key,
            ros_type=self.type,
            delivery=self.delivery,
            stages=tuple(self.stages),
            linger_ns=aggregate_linger(self.stages) if self.linger is None else self.linger,
            claim_check=self.claim_check,
        )


MAX_LINGER_NS = 60 * _NS
AGGREGATE_LINGER_MAX_NS = 5 * _NS


def aggregate_linger(stages: list[StageSpec]) -> int | None:
    """The default linger of a mapping with an aggregate stage (see ``MappingConfig.linger``)."""
    periods = [s.hop or s.window for s in stages if isinstance(s, AggregateSpec)]
    return min([*periods, AGGREGATE_LINGER_MAX_NS]) if periods else None


def _check_template(value: str, info: ValidationInfo, what: str, *, topic: bool) -> str:
    try:
        template = Template.parse(value, what=what)
        source = info.data.get("from_")
        if source is not None:
            check_captures(template, TopicPattern.parse(source), what, "")
        if topic:
            check_topic_literal(template, "")
    except MappingError as exc:
        raise ValueError(_why(exc)) from None
    return value


class RobotMappingConfig(MappingConfig):
    """A robot type's mapping template: ``from`` must capture ``{robot}`` as one segment."""

    @field_validator("from_")
    @classmethod
    def _robot(cls, value: str) -> str:
        if not TopicPattern.parse(value).is_single("robot"):
            raise ValueError(
                f"{value!r}: a robot type's mappings capture the robot as one segment, e.g. '/{{robot}}/imu'"
            )
        return value


class RobotTypeConfig(Section):
    """A robot type: the robot namespaces it matches and the mappings each of its robots gets."""

    match: NamespaceGlob
    """Glob over robot namespaces, e.g. ``/tb4_*``."""
    mappings: list[RobotMappingConfig] = []


class RegistrationSection(Section):
    """How robots register: discovered in the ROS graph or explicitly on a topic."""

    topic: RosTopic = "/fleetlink/register"
    """ROS topic on which robots may register explicitly."""
    discover: bool = True
    """Register robots found in the ROS graph whose namespace matches a robot type."""
    grace_period: DurationNs = 5 * _NS
    """How long a robot may be gone (liveliness lost) before it is deregistered."""
    hold: DurationNs = 5 * _NS
    """How long samples that come before their robot's registration wait for it (a robot that
    publishes at once can outrun its discovery); those whose robot has not registered by then
    are counted as unmapped. 0: not held (counted as unmapped at once)."""


class SpoolSection(Section):
    """The durable spool on local disk: its folder, size, full policy and fsync policy."""

    dir: Path
    delivery: Literal["at_least_once", "exactly_once"] = "at_least_once"
    """How the spool's records reach Kafka: ``exactly_once`` has the uplink write each record once
    (Kafka transactions, read them with ``isolation.level=read_committed``; docs/exactly-once.md)."""
    max_bytes: ByteSize = ByteSize(1 << 30)
    segment_bytes: ByteSize = ByteSize(16 << 20)
    policy: FullPolicy = "block"
    block_timeout: DurationNs = 1 * _NS
    fsync: FsyncPolicy = "interval"
    fsync_interval: DurationNs = 100_000_000
    fsync_batch: int = Field(default=1000, ge=1)

    @model_validator(mode="after")
    def _coherent(self) -> SpoolSection:
        try:
            self.options()
        except EdgeError as exc:
            raise ValueError(str(exc)) from None
        return self

    def options(self) -> SpoolOptions:
        """The spool's options, with the durations in seconds and milliseconds."""
        return SpoolOptions(
            max_bytes=int(self.max_bytes),
            segment_bytes=int(self.segment_bytes),
            policy=self.policy,
            block_timeout_s=self.block_timeout / _NS,
            fsync=self.fsync,
            fsync_interval_ms=max(1, self.fsync_interval // 1_000_000),
            fsync_batch=self.fsync_batch,
        )


class MemorySection(Section):
    """The in-memory buffer of ``best_effort`` mappings."""

    max_bytes: ByteSize = ByteSize(64 << 20)
    max_records: int = Field(default=100_000, ge=1)

    def buffer(self) -> MemoryBuffer:
        """A new, empty memory buffer with these bounds."""
        return MemoryBuffer(max_bytes=int(self.max_bytes), max_records=self.max_records)


BASE_RSS = 256 << 20
"""The edge process with nothing held (measured 170-200 MB with 1,000 subscriptions and the
standard type store; rounded up)."""
EARLY_MAX_SAMPLES = 16_384
"""Samples that may wait for their robot's registration at once (``registration.hold``)."""
EARLY_MAX_BYTES = 16 << 20
"""Payload bytes that may wait for their robot's registration at once."""


class IntakeSection(Section):
    """What the edge holds between receiving a sample and spooling its records: one queue for
    every subscription, bounded in samples and in bytes. A sample that does not fit is dropped
    and counted (``intake.dropped``): the robots never wait, and the edge's memory stays bounded
    whatever the backlog (docs/edge.md, "Memory")."""

    max_samples: int = Field(default=100_000, ge=1, le=10_000_000)
    max_bytes: ByteSize = ByteSize(64 << 20)
    lag_alarm: DurationNs = 2 * _NS
    """Health turns ``degraded`` while samples wait longer than this between receipt and spool."""
    coalesce: DurationNs = Field(default=1_000_000, ge=0, le=100_000_000)
    """A sample that wakes the receive thread makes it wait this long before reading on, so the
    samples arriving meanwhile are read from the socket together: one wake-up for many samples
    instead of one each. Adds at most that much latency; ``0s`` turns it off. Samples read from a
    backlog (a burst) never wait (docs/edge.md, "Receiving")."""
    busy_coalesce: DurationNs = Field(default=10_000_000, ge=0, le=100_000_000)
    """The same wait while samples arrive at 1,500 a second or more (a fleet's steady flow), where
    wake-ups cost the most and a few ms of latency the least."""


class WanSection(Section):
    """How records cross the WAN to the uplink: batching, acknowledgements, retries, compression."""

    # Defaults measured with bench/bench_e2e.py (docs/benchmarks.md): batches of 500 records cost
    # the edge 14% and the uplink 12% more CPU per record than batches of up to 2,000 (each batch
    # is a Zenoh query with its reply callbacks on both sides); 1 MiB, about 1,500 IMU records, is
    # then what bounds a batch. Four batches in flight keep the re-send window (duplicates after a
    # crash or timeout) at about the size it had with 8 x 500.
    batch_max_records: int = Field(default=2000, ge=1, le=100_000)
    """At most this many records per batch (``batch_max_bytes`` may end it earlier)."""
    batch_max_bytes: ByteSize = ByteSize(1 << 20)
    linger: DurationNs = 20_000_000
    """How long a partial batch may wait for more records."""
    ack_timeout: DurationNs = 10 * _NS
    max_in_flight: int = Field(default=4, ge=1, le=1024)
    """Batches of a stream sent and not yet answered."""
    retry_backoff_min: DurationNs = 200_000_000
    retry_backoff_max: DurationNs = 30 * _NS
    codec: Codec = "zstd"
    max_record_bytes: ByteSize | None = None
    """The largest Kafka record the uplink produces. Default: what the uplink says in its
    acknowledgements (kept in the spool folder; 1,000,000 until one came). Set, it is used until
    the uplink says less."""
    oversize: Literal["dead_letter", "drop"] = "dead_letter"
    """A record above that limit never crosses the WAN: ``dead_letter`` sends a dead letter in
    its place (size and SHA-256, no value), ``drop`` only counts it. A mapping with a
    ``claim_check`` sends the payload to the object store first."""

    @model_validator(mode="after")
    def _backoff(self) -> WanSection:
        if not 0 < self.retry_backoff_min <= self.retry_backoff_max:
            raise ValueError("retry_backoff_min must be above 0s and at most retry_backoff_max")
        if self.ack_timeout <= 0:
            raise ValueError("ack_timeout must be above 0s")
        return self


class TopicsSection(Section):
    """Kafka topics the edge writes to besides the mappings' own."""

    dead_letter: KafkaTopic = "fleetlink.dead-letter"
    """Records that could not be received, decoded, mapped or encoded (raw bytes + reason)."""
    registrations: KafkaTopic = "fleetlink.robots"
    """Robot registration events, keyed by robot (create it with cleanup.policy=compact)."""


class AdminSection(Section):
    """The edge's admin HTTP API."""

    listen: str = "127.0.0.1:8480"
    """host:port of the admin HTTP API."""

    @field_validator("listen")
    @classmethod
    def _host_port(cls, value: str) -> str:
        host, sep, port = value.rpartition(":")
        if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
            raise ValueError(f"{value!r} is not host:port")
        return value


class EdgeConfig(Section):
    """Everything one edge process needs; one YAML file."""

    site: Site
    edge_id: KeyChunk = Field(default_factory=default_edge_id)
    ros: RosSection = RosSection()
    zenoh: ZenohSection = ZenohSection()
    robot_types: dict[KeyChunk, RobotTypeConfig] = {}
    mappings: list[MappingConfig] = []
    """Site-level mappings, not tied to a robot type (patterns may still capture ``{robot}``)."""
    registration: RegistrationSection = RegistrationSection()
    spool: SpoolSection
    memory: MemorySection = MemorySection()
    intake: IntakeSection = IntakeSection()
    wan: WanSection = WanSection()
    topics: TopicsSection = TopicsSection()
    admin: AdminSection | None = None
    objects: ObjectStoreSection | None = None
    """The S3-compatible object store of claim-checked payloads (docs/images.md)."""

    def memory_bound(self) -> int:
        """The edge's resident memory at most, in bytes, whatever the backlog: the base process
        (interpreter, libraries, type store, Zenoh sessions), the intake (samples plus the
        bookkeeping of each), the spool's frames kept in memory, the memory buffer, the WAN
        batches in flight (raw and compressed) and the group being built, and the samples that
        wait for their robot's registration."""
        recent = min(32 << 20, int(self.spool.max_bytes))
        intake = int(self.intake.max_bytes) + self.intake.max_samples * 160
        wan = self.wan.max_in_flight * 2 * int(self.wan.batch_max_bytes) + 2 * int(self.wan.batch_max_bytes)
        early = EARLY_MAX_BYTES + EARLY_MAX_SAMPLES * 160 if self.registration.hold else 0
        return BASE_RSS + intake + recent + int(self.memory.max_bytes) + wan + early

    @model_validator(mode="after")
    def _unique_names(self) -> EdgeConfig:
        seen: dict[str, str] = {}
        places = [(m.name, f"mappings[{i}]") for i, m in enumerate(self.mappings)]
        places += [
            (m.name, f"robot_types.{t}.mappings[{i}]")
            for t, rt in self.robot_types.items()
            for i, m in enumerate(rt.mappings)
        ]
        if self.objects is None:
            claimed = [(m.name, f"mappings[{i}]") for i, m in enumerate(self.mappings) if m.claim_check]
            claimed += [
                (m.name, f"robot_types.{t}.mappings[{i}]")
                for t, rt in self.robot_types.items()
                for i, m in enumerate(rt.mappings)
                if m.claim_check
            ]
            if claimed:
                name, where = claimed[0]
                raise ValueError(
                    f"{where}.claim_check: mapping {name!r} claim-checks its payloads, but the edge "
                    "has no object store: add an 'objects' section"
                )
        for name, where in places:
            if name in seen:
                raise ValueError(
                    f"mapping name {name!r} is used twice ({seen[name]} and {where}); "
                    "names must be unique per edge"
                )
            seen[name] = where
        return self

    def robot_type_specs(self) -> list[RobotTypeSpec]:
        """Every robot type as a ``RobotTypeSpec`` with its mapping templates."""
        return [
            RobotTypeSpec(name=n, match=t.match, mappings=tuple(m.spec() for m in t.mappings))
            for n, t in self.robot_types.items()
        ]

    def mapping_table(self) -> MappingTable:
        """A fresh mapping table with every declared mapping (no robots registered yet)."""
        return MappingTable(self.robot_type_specs(), [m.spec() for m in self.mappings])


__all__ = [
    "AdminSection",
    "EdgeConfig",
    "MappingConfig",
    "MemorySection",
    "RegistrationSection",
    "RobotMappingConfig",
    "RobotTypeConfig",
    "RosSection",
    "SpoolSection",
    "TopicsSection",
    "WanSection",
    "default_edge_id",
]
