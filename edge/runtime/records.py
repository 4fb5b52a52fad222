"""ROS samples -> Kafka records (pure: no sockets, no disk, the time is passed in).

For every mapping a sample's topic feeds (``MappingTable.match``):

* **fast path** (no stages, no ``{msg.…}`` in the topic or key): the Avro body comes straight
  from the CDR bytes through the type's generated converter, framed as an Avro single object;
* otherwise the CDR is decoded to a dict, run through the mapping's stages, and encoded with the
  (possibly derived) schema; untouched samples still take the fast encoder.

Anything that goes wrong with one sample (a payload the subscriber refused, a type not in the
type store, CDR that does not decode, a topic template that renders an illegal name, a value
that does not fit its schema, a record too large) becomes a **dead-letter record**: the raw
bytes as value and the reason, stage and ROS key in headers. The next sample flows.

A record above the uplink's Kafka limit (``max_record_bytes``, learned from its answers) never
crosses the WAN: it becomes a dead letter without its value, or is dropped and counted
(``oversize``). A mapping with a ``claim_check`` hands each record to the uploader as a
``ClaimJob`` (``drain_claims``): a large payload goes to the object store and ``finish_claim``
makes the record with its reference once it is stored (docs/images.md).
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import Any, Literal, Protocol

from fleetlink.edge.claim_check import (
    ClaimCheckError,
    Claimed,
    ClaimJob,
    Upload,
    claim_schema,
    content_type_for,
    object_key,
    ref_field,
)
from fleetlink.edge.errors import RenderError
from fleetlink.edge.mapping import BoundMapping, Delivery
from fleetlink.edge.runtime.encoding import AvroWriter, SchemaIdentity, identity_of
from fleetlink.edge.runtime.errors import EncodingError
from fleetlink.edge.runtime.fastpath import FastPlan, Lane, run_plan
from fleetlink.edge.runtime.outgoing import MappingCounters, Outgoing
from fleetlink.edge.stages import Pipeline, Sample, StageConfigError, build_pipeline
from fleetlink.roswire.errors import AttachmentError, KeyParseError, PayloadError, RoswireError
from fleetlink.roswire.subscriber import RosSample
from fleetlink.schemas.codec import Codec
from fleetlink.schemas.errors import SchemaError
from fleetlink.wire import SINGLE_OBJECT_MAGIC, PayloadTemplate, Record, single_object
from fleetlink.wire import headers as names
from fleetlink.wire.limits import DEFAULT_MAX_RECORD_BYTES, SINGLE_OBJECT_EXTRA, kafka_record_bytes
from fleetlink.wire.robot_events import EDGE_HEADER, ROBOT_HEADER, SITE_HEADER

H_SOURCE_TOPIC = names.SOURCE_TOPIC
H_ROS_TYPE = names.ROS_TYPE
H_TYPE_HASH = names.TYPE_HASH
H_SITE = SITE_HEADER
H_ROBOT = ROBOT_HEADER
H_SEQ = names.SEQ
H_MAPPING = names.MAPPING
H_EDGE = EDGE_HEADER
# dead letters (the same names the uplink uses for the ones it makes)
H_DLQ_STAGE = names.DLQ_STAGE
H_DLQ_REASON = names.DLQ_REASON
H_DLQ_TOPIC = names.DLQ_TOPIC
H_DLQ_SIZE = names.DLQ_SIZE
H_DLQ_SHA256 = names.DLQ_SHA256
H_DLQ_TRUNCATED = names.DLQ_TRUNCATED
H_ROS_KEY = names.ROS_KEY

Matcher = Callable[[str], Sequence[BoundMapping]]
_PLAN_CACHE_SIZE = 4096
FAST_MARGIN = 16 << 10
"""Room the fast path leaves below the record limit for a record's key and headers: a value
within it of the limit takes the general path, which measures the whole record."""
DEAD_LETTER_MARGIN = 64 << 10
"""Room a dead letter's value leaves below the record limit for its headers."""
Oversize = Literal["dead_letter", "drop"]


class TypeSource(Protocol):
    """Where codecs come from (``schemas.codec.get_codec`` over the edge's type store)."""

    def codec(self, typename: str) -> Codec:
        """The codec of the ROS type ``typename``; raises ``SchemaError`` when none can be made."""
        ...


@dataclass(frozen=True, slots=True)
class WireSample(Sample):
    """A stage ``Sample`` that remembers where it came from (kept when a stage forwards it)."""

    typename: str = ""
    type_hash: str = ""
    seq: int | None = None
    key_expr: str = ""


@dataclass(frozen=True, slots=True)
class Origin:
    """Where a record comes from: what its headers and a dead letter say about it."""

    topic: str
    typename: str
    type_hash: str
    seq: int | None
    key_expr: str
    stamp_ns: int
    raw: bytes | None


@dataclass(frozen=True, slots=True)
class _Claim:
    """How a claim-checking mapping writes its records (``edge.claim_check``)."""

    field: str
    ref: str
    above: int
    writer: AvroWriter


@dataclass(slots=True)
class _Route:
    """How one mapping handles one ROS type."""

    stages: tuple[Any, ...]
    codec: Codec
    source: SchemaIdentity
    pipeline: Pipeline | None
    writer: AvroWriter | None
    """Set when the stages change the schema (project, aggregate)."""
    fast: bool
    problem: str | None = None
    dead_lettered_problem: bool = False
    last_totals: dict[str, int] = field(default_factory=dict)
    claim: _Claim | None = None
    claim_spec: Any = None


@dataclass(frozen=True, slots=True)
class ClaimContext:
    """What ``finish_claim`` needs to make a claim job's record (the maker's own data)."""

    bound: BoundMapping
    claim: _Claim
    origin: Origin
    topic: str
    key: str
    value: dict[str, Any]
    """The message with its payload field emptied (a job with an upload) or as it was."""
    encoded: bytes | None
    """The record's value, when the payload stays inline."""
    payload: bytes


@dataclass(slots=True)
class ClaimStats:
    """What became of the payloads of claim-checking mappings: kept inline, stored, or failed."""

    inline: int = 0
    """Records of claim-checking mappings whose payload stayed in the record."""
    claimed: int = 0
    """Records whose payload went to the object store."""
    failed: int = 0
    """Records dead-lettered because their payload could not be stored."""


class RecordMaker:
    """Turns samples into ``Outgoing`` records; not thread-safe (one processing thread)."""

    def __init__(
        self,
        *,
        site: str,
        edge_id: str,
        match: Matcher,
        types: TypeSource,
        dead_letter_topic: str,
        max_value_bytes: int = 16 << 20,
        max_dead_letter_bytes: int = 900_000,
        on_schema: Callable[[bytes, str], None] | None = None,
        max_record_bytes: int = DEFAULT_MAX_RECORD_BYTES,
        oversize: Oversize = "dead_letter",
        object_prefix: str = "",
        awaits_robot: Callable[[str], bool] | None = None,
    ) -> None:
        self.site = site
        self.edge_id = edge_id
        self._match = match
        self._awaits_robot = awaits_robot
        """Whether a topic no mapping takes will be taken once its robot registers."""
        self._types = types
        self.dead_letter_topic = dead_letter_topic
        self.max_value_bytes = max_value_bytes
        self.max_dead_letter_bytes = max_dead_letter_bytes
        self._on_schema = on_schema or _ignore_schema
        self._site_header = (H_SITE, site.encode())
        self._edge_header = (H_EDGE, edge_id.encode())
        self._routes: dict[tuple[str, str], _Route] = {}
        self._plans: dict[str, FastPlan] = {}
        self._unknown_types: set[str] = set()
        self.counters: dict[str, MappingCounters] = {}
        self.unknown_type_samples = 0
        self.rejected = 0
        self.unmapped: dict[str, int] = {}
        """Per ROS topic, samples on the general path that no mapping took (no record made)."""
        """Samples the subscriber refused (no attachment, bad CDR header, bad key)."""
        self.oversize = oversize
        self.oversized = 0
        """Records kept off the WAN because they pass the record limit (dead-lettered or dropped)."""
        self.object_prefix = object_prefix
        self.max_record_bytes = max_record_bytes
        self.fast_value_limit = max_value_bytes
        self.set_record_limit(max_record_bytes)
        self.claims: list[ClaimJob] = []
        """Jobs made since the last ``drain_claims``."""
        self.claim_stats = ClaimStats()

    def set_record_limit(self, max_record_bytes: int) -> None:
        """The largest Kafka record the uplink produces (``edge.runtime.limits.RecordLimit``)."""
        self.max_record_bytes = max_record_bytes
        self.fast_value_limit = min(self.max_value_bytes, max(1024, max_record_bytes - FAST_MARGIN))

    def drain_claims(self) -> list[ClaimJob]:
        """The claim jobs made since the last call, in order (for the uploader)."""
        jobs, self.claims = self.claims, []
        return jobs

    # -- entry points ----------------------------------------------------------------------------
    def make(self, sample: RosSample, now_ns: int) -> list[Outgoing]:
        """Every record one received sample produces (possibly none, possibly dead letters)."""
        bounds = self._match(sample.topic)
        plan = self._plans.get(sample.key)  # the data key names topic, type and hash
        if plan is None or plan.bounds is not bounds or plan.topic != sample.topic:
            plan = self._plan(sample, bounds)
        if not bounds:  # no mapping takes it (its robot is not registered, or not yet): counted
            self.count_unmapped(sample.topic)
            if plan.lanes is None:  # kept on the general path while samples waited: dropped natively now
                self._plan(sample, bounds)
            return []
        if plan.lanes is not None:
            return run_plan(plan, sample, self.fast_value_limit, self._one, now_ns)
        out: list[Outgoing] = []
        for bound in bounds:
            counters = self._counters(bound.name)
            counters.received += 1
            if bound.ros_type is not None and bound.ros_type != sample.typename:
                counters.type_mismatch += 1
                continue
            self._one(bound, sample, now_ns, out)
        return out

    def takes(self, topic: str) -> bool:
        """Whether a mapping takes ``topic`` now."""
        return bool(self._match(topic))

    def waits_for_robot(self, sample: RosSample) -> bool:
        """Whether no mapping takes ``sample``'s topic yet but one will once its robot registers
        (``edge.runtime.early``)."""
        return bool(
            self._awaits_robot is not None
            and not self._match(sample.topic)
            and self._awaits_robot(sample.topic)
        )

    def keep_general(self, sample: RosSample) -> None:
        """Samples of ``sample``'s data key keep coming to the general path (one waits for its
        robot): no plan that drops them natively is made for it meanwhile."""
        self._plans[sample.key] = FastPlan(sample.topic, (), None)

    def count_unmapped(self, topic: str) -> None:
        """A sample of ``topic`` that no mapping took: no record, counted."""
        self.unmapped[topic] = self.unmapped.get(topic, 0) + 1

    def _plan(self, sample: RosSample, bounds: Sequence[BoundMapping]) -> FastPlan:
        """The fast lanes of ``sample``'s (topic, type, hash), when every mapping allows them."""
        lanes: list[Lane] = []
        mismatched: list[MappingCounters] = []
        plan: FastPlan | None = None
        for bound in bounds:
            if bound.ros_type is not None and bound.ros_type != sample.typename:
                mismatched.append(self._counters(bound.name))
                continue
            route = self._route(bound, sample.typename)
            if (
                route is None
                or route.problem is not None
                or not route.fast
                or bound.topic_error is not None
                or bound.kafka_topic is None
                or bound.key is None
            ):
                plan = FastPlan(sample.topic, bounds, None)
                break
            origin = Origin(sample.topic, sample.typename, sample.type_hash, None, sample.key, 0, None)
            headers = self._headers(bound, origin)  # all but fleetlink.seq: it comes with each sample
            template = PayloadTemplate(bound.kafka_topic, bound.key.encode("utf-8"), headers)
            lanes.append(
                Lane(
                    bound,
                    self._counters(bound.name),
                    route.codec,
                    route.codec.cdr_to_avro,
                    SINGLE_OBJECT_MAGIC + route.source.fingerprint,
                    template,
                    bound.delivery,
                    bound.linger_s,
                )
            )
        if plan is None:
            plan = FastPlan(sample.topic, bounds, tuple(lanes), tuple(mismatched))
        if len(self._plans) >= _PLAN_CACHE_SIZE:
            self._plans.clear()
        self._plans[sample.key] = plan
        return plan

    def plan_for(self, key: str) -> FastPlan | None:
        """The fast plan made for data key ``key`` (by the last sample of it), if any."""
        return self._plans.get(key)

    def tick(self, now_ns: int) -> list[Outgoing]:
        """Time-driven stage output (held samples, heartbeats, closed windows)."""
        out: list[Outgoing] = []
        for (name, _typename), route in list(self._routes.items()):
            if route.pipeline is None:
                continue
            for result in route.pipeline.tick(now_ns):
                bound = next((b for b in self._match(result.topic) if b.name == name), None)
                if bound is None:  # the robot or the mapping is gone
                    self._counters(name).dropped += 1
                    continue
                self._emit(bound, route, result, out)
            self._account(name, route)
        return out

    def rejected_sample(self, topic: str, error: RoswireError, now_ns: int) -> list[Outgoing]:
        """A sample the subscriber refused (``on_error``) -> one dead letter with its bytes."""
        self.rejected += 1
        bounds = self._match(topic)
        raw = b""
        key_expr = topic
        if isinstance(error, PayloadError):
            raw, key_expr = error.raw, error.key
        elif isinstance(error, AttachmentError):  # the sample's bytes when the subscriber knew them
            raw, key_expr = error.payload or error.raw, error.key or topic
        elif isinstance(error, KeyParseError):
            key_expr = error.key
        bound = bounds[0] if bounds else None
        if bound is not None:
            self._counters(bound.name).dead_lettered += 1
        typename = error.typename if isinstance(error, PayloadError) and error.typename else ""
        origin = Origin(topic, typename, "", None, key_expr, now_ns, raw)
        return [self._dead_letter("receive", str(error), origin, bound, _delivery_of(bounds))]

    # -- one mapping, one sample -----------------------------------------------------------------
    def _one(self, bound: BoundMapping, sample: RosSample, now_ns: int, out: list[Outgoing]) -> None:
        stamp_ns = sample.source_ts_ns if sample.source_ts_ns else sample.received_ns
        origin = Origin(
            sample.topic, sample.typename, sample.type_hash, sample.seq, sample.key, stamp_ns, sample.payload
        )
        route = self._route(bound, sample.typename)
        problem = self._problem(bound, route, sample.typename)
        if problem is not None:
            self._dead(problem[0], problem[1], origin, bound, out)
            return
        if route is None or route.problem is not None:
            return
        if route.fast:
            try:
                body = route.codec.cdr_to_avro(sample.payload)
                value = single_object(route.source.fingerprint, body)
                topic, key = bound.render_topic(), bound.render_key()
            except (SchemaError, RenderError) as exc:
                self._dead("map" if isinstance(exc, RenderError) else "decode", str(exc), origin, bound, out)
                return
            self._finish(bound, (topic, key, value), origin, out)
            return
        try:
            decoded = route.codec.decode(sample.payload)
        except SchemaError as exc:
            self._dead("decode", str(exc), origin, bound, out)
            return
        wire = WireSample(
            robot=bound.robot or "",
            topic=sample.topic,
            stamp_ns=stamp_ns,
            value=decoded,
            raw=sample.payload,
            typename=sample.typename,
            type_hash=sample.type_hash,
            seq=sample.seq,
            key_expr=sample.key,
        )
        if route.pipeline is None:
            self._emit(bound, route, wire, out)
            return
        for result in route.pipeline.process(wire, now_ns):
            self._emit(bound, route, result, out)
        self._account(bound.name, route)

    def _problem(self, bound: BoundMapping, route: _Route | None, typename: str) -> tuple[str, str] | None:
        """A per-(mapping, type) problem: dead-lettered the first time, then only counted
        (``None``: no problem, or already reported: ``route`` is None or unusable then)."""
        if route is None:  # the type is not in the type store
            self.unknown_type_samples += 1
            if typename in self._unknown_types:
                self._counters(bound.name).dropped += 1
                return None
            self._unknown_types.add(typename)
            return (
                "decode",
                f"unknown ROS type {typename!r}: not in the edge's type store (add its "
                "package to ros.message_paths); further samples are only counted",
            )
        if route.problem is None:
            return None
        if route.dead_lettered_problem:
            self._counters(bound.name).dropped += 1
            return None
        route.dead_lettered_problem = True
        return ("setup", route.problem)

    def _dead(
        self, stage: str, reason: str, origin: Origin, bound: BoundMapping, out: list[Outgoing]
    ) -> None:
        self._counters(bound.name).dead_lettered += 1
        out.append(self._dead_letter(stage, reason, origin, bound, bound.delivery))

    def _emit(self, bound: BoundMapping, route: _Route, result: Sample, out: list[Outgoing]) -> None:
        """Encode one stage output (or an unstaged decoded sample) and add its record."""
        if isinstance(result, WireSample):
            origin = Origin(
                result.topic,
                result.typename,
                result.type_hash,
                result.seq,
                result.key_expr,
                result.stamp_ns,
                result.raw,
            )
        else:  # made by a stage (aggregate, project): no wire identity of its own
            origin = Origin(
                result.topic,
                route.codec.typename,
                route.codec.type_hash,
                None,
                "",
                result.stamp_ns,
                result.raw,
            )
        if route.claim is not None:
            self._claim(bound, route.claim, result, origin, out)
            return
        raw = result.raw
        try:
            if route.writer is None:
                body = (
                    route.codec.cdr_to_avro(raw)
                    if raw is not None
                    else route.codec.encode_datum(dict(result.value))
                )
                value = single_object(route.source.fingerprint, body)
            else:
                value = single_object(route.writer.fingerprint, route.writer.body(result.value))
            topic = bound.render_topic(result.value)
            key = bound.render_key(result.value)
        except (SchemaError, EncodingError, RenderError) as exc:
            if raw is None:
                origin = Origin(
                    origin.topic,
                    origin.typename,
                    origin.type_hash,
                    origin.seq,
                    origin.key_expr,
                    origin.stamp_ns,
                    repr(result.value).encode("utf-8", "replace"),
                )
            self._dead("map" if isinstance(exc, RenderError) else "encode", str(exc), origin, bound, out)
            return
        self._finish(bound, (topic, key, value), origin, out)

    def _finish(
        self, bound: BoundMapping, made: tuple[str, str, bytes], origin: Origin, out: list[Outgoing]
    ) -> None:
        """Add the record ``made`` = (Kafka topic, key, value), unless it is too large: then the
        ``oversize`` policy (a dead letter with its size and SHA-256, or a counted drop)."""
        topic, key, value = made
        key_bytes = key.encode("utf-8")
        headers = self._headers(bound, origin)
        problem = self._too_large(key_bytes, value, headers)
        if problem is not None:
            self.oversized += 1
            counters = self._counters(bound.name)
            if self.oversize == "drop":
                counters.dropped += 1
                return
            if origin.raw is None:
                origin = replace(origin, raw=value)
            counters.dead_lettered += 1
            out.append(self._dead_letter("size", problem, origin, bound, bound.delivery, intended=topic))
            return
        self._counters(bound.name).emitted += 1
        out.append(
            Outgoing.of(
                bound.delivery,
                Record(
                    kafka_topic=topic,
                    key=key_bytes,
                    value=value,
                    headers=headers,
                    timestamp_ms=origin.stamp_ns // 1_000_000,
                ),
                bound.linger_s,
            )
        )

    def _too_large(self, key: bytes, value: bytes, headers: Sequence[tuple[str, bytes]]) -> str | None:
        """Why a record cannot go (the edge's own limit, or the uplink's), or None when it fits."""
        if len(value) > self.max_value_bytes:
            return (
                f"Avro value of {len(value)} bytes exceeds the edge's record limit of "
                f"{self.max_value_bytes} bytes"
            )
        size = kafka_record_bytes(len(key), len(value) - SINGLE_OBJECT_EXTRA, headers)
        if size > self.max_record_bytes:
            return (
                f"record of {size} bytes exceeds the uplink's Kafka limit of {self.max_record_bytes} "
                "bytes (kafka.message_max_bytes): kept off the WAN"
            )
        return None

    # -- claim checks ----------------------------------------------------------------------------
    def _claim(
        self, bound: BoundMapping, claim: _Claim, result: Sample, origin: Origin, out: list[Outgoing]
    ) -> None:
        """Make the claim job of one record: its payload stays inline when small enough, else it is
        uploaded first. The job goes to ``claims``; its record comes from ``finish_claim``."""
        value = dict(result.value)
        payload = value.get(claim.field)
        if not isinstance(payload, bytes | bytearray | memoryview):
            self._dead("encode", f"claim_check: field {claim.field!r} holds no bytes", origin, bound, out)
            return
        payload = bytes(payload)
        try:
            topic, key = bound.render_topic(result.value), bound.render_key(result.value)
        except RenderError as exc:
            self._dead("map", str(exc), origin, bound, out)
            return
        value[claim.ref] = None
        encoded: bytes | None = None
        if len(payload) <= claim.above:
            try:
                encoded = single_object(claim.writer.fingerprint, claim.writer.body(value))
            except EncodingError as exc:
                self._dead("encode", str(exc), _with_raw(origin, value), bound, out)
                return
            if self._too_large(key.encode("utf-8"), encoded, self._headers(bound, origin)) is not None:
                encoded = None  # the whole record does not fit: the payload goes to the store
        upload: Upload | None = None
        if encoded is None:
            digest = hashlib.sha256(payload).hexdigest()
            content_type = content_type_for(value)
            name = object_key(
                prefix=self.object_prefix,
                site=self.site,
                robot=bound.robot,
                mapping=bound.name,
                stamp_ns=origin.stamp_ns,
                sha256=digest,
                content_type=content_type,
            )
            upload = Upload(name, payload, digest, content_type)
            value[claim.field] = b""
        context = ClaimContext(bound, claim, origin, topic, key, value, encoded, payload)
        lane = f"{bound.name}/{bound.robot or ''}"
        self.claims.append(ClaimJob(lane, upload, context, len(payload) if upload else 0))

    def finish_claim(self, claimed: Claimed) -> list[Outgoing]:
        """The record of a finished claim job (or its dead letter, when its payload was not stored)."""
        job = claimed.job
        ctx: ClaimContext = job.context
        bound, claim, origin = ctx.bound, ctx.claim, ctx.origin
        out: list[Outgoing] = []
        if claimed.error is not None:
            self.claim_stats.failed += 1
            self._dead("claim_check", claimed.error, replace(origin, raw=ctx.payload), bound, out)
            return out
        if job.upload is None or claimed.ref is None:
            self.claim_stats.inline += 1
            encoded = ctx.encoded or b""
        else:
            self.claim_stats.claimed += 1
            value = {**ctx.value, claim.ref: claimed.ref.as_datum()}
            try:
                encoded = single_object(claim.writer.fingerprint, claim.writer.body(value))
            except EncodingError as exc:
                self._dead("encode", str(exc), replace(origin, raw=ctx.payload), bound, out)
                return out
        self._finish(bound, (ctx.topic, ctx.key, encoded), origin, out)
        return out

    # -- routes ----------------------------------------------------------------------------------
    def _route(self, bound: BoundMapping, typename: str) -> _Route | None:
        fast = not bound.stages and not bound.needs_message_fields and bound.claim_check is None
        route = self._routes.get((bound.name, typename))
        if (
            route is not None
            and route.stages is bound.stages
            and route.fast == fast
            and route.claim_spec is bound.claim_check
        ):
            return route
        try:
            codec = self._types.codec(typename)
        except SchemaError:
            return None
        source = identity_of(codec.schema)
        self._on_schema(source.fingerprint, source.json)
        pipeline: Pipeline | None = None
        writer: AvroWriter | None = None
        problem: str | None = None
        if bound.stages:
            try:
                pipeline = build_pipeline(list(bound.stages), name=bound.name)
                derived = pipeline.output_schema(codec.schema)
                if derived != codec.schema:
                    writer = AvroWriter(derived)
                    self._on_schema(writer.fingerprint, writer.identity.json)
            except StageConfigError as exc:
                problem = f"mapping {bound.name!r} cannot handle {typename}: {exc}"
                pipeline = None
        claim: _Claim | None = None
        spec = bound.claim_check
        if spec is not None and problem is None:
            try:
                schema = claim_schema(writer.schema if writer is not None else codec.schema, spec.field)
            except ClaimCheckError as exc:
                problem = f"mapping {bound.name!r} cannot handle {typename}: {exc}"
            else:
                claim_writer = AvroWriter(schema)
                self._on_schema(claim_writer.fingerprint, claim_writer.identity.json)
                claim = _Claim(spec.field, ref_field(spec.field), int(spec.above), claim_writer)
        route = _Route(
            stages=bound.stages,
            codec=codec,
            source=source,
            pipeline=pipeline,
            writer=writer,
            fast=fast,
            problem=problem,
            claim=claim,
            claim_spec=spec,
        )
        self._routes[(bound.name, typename)] = route
        return route

    def _account(self, name: str, route: _Route) -> None:
        """Fold the pipeline's drop counters into the mapping's (deltas since the last call)."""
        if route.pipeline is None:
            return
        totals = route.pipeline.totals()
        now = {"dropped": totals.dropped + totals.late + totals.errors}
        delta = now["dropped"] - route.last_totals.get("dropped", 0)
        if delta:
            self._counters(name).dropped += delta
        route.last_totals = now

    def stage_counters(self) -> dict[str, dict[str, dict[str, int]]]:
        """``{mapping: {stage: counters}}`` summed over the ROS types the mapping has seen."""
        out: dict[str, dict[str, dict[str, int]]] = {}
        for (name, _typename), route in self._routes.items():
            if route.pipeline is None:
                continue
            per_stage = out.setdefault(name, {})
            for stage, counts in route.pipeline.stage_counters().items():
                into = per_stage.setdefault(stage, dict.fromkeys(counts, 0))
                for k, v in counts.items():
                    into[k] = into.get(k, 0) + v
        return out

    # -- records ---------------------------------------------------------------------------------
    def _counters(self, name: str) -> MappingCounters:
        counters = self.counters.get(name)
        if counters is None:
            counters = self.counters[name] = MappingCounters()
        return counters

    def _headers(self, bound: BoundMapping | None, origin: Origin) -> tuple[tuple[str, bytes], ...]:
        headers = [(H_SOURCE_TOPIC, origin.topic.encode())]
        if origin.typename:
            headers.append((H_ROS_TYPE, origin.typename.encode()))
        if origin.type_hash:
            headers.append((H_TYPE_HASH, origin.type_hash.encode()))
        headers.append(self._site_header)
        headers.append(self._edge_header)
        if bound is not None and bound.robot:
            headers.append((H_ROBOT, bound.robot.encode()))
        if origin.seq is not None:
            headers.append((H_SEQ, str(origin.seq).encode()))
        if bound is not None:
            headers.append((H_MAPPING, bound.name.encode()))
        return tuple(headers)

    def _dead_letter(
        self,
        stage: str,
        reason: str,
        origin: Origin,
        bound: BoundMapping | None,
        delivery: Delivery,
        *,
        intended: str | None = None,
    ) -> Outgoing:
        if intended is None and bound is not None:
            intended = bound.kafka_topic or bound.topic_template.text
        raw = origin.raw or b""
        headers = [
            *self._headers(bound, origin),
            (H_DLQ_STAGE, stage.encode()),
            (H_DLQ_REASON, reason.encode("utf-8", "replace")[:2000]),
            (H_DLQ_TOPIC, (intended or "").encode()),
            (H_DLQ_SIZE, str(len(raw)).encode()),
            (H_ROS_KEY, origin.key_expr.encode("utf-8", "replace")),
        ]
        value = raw
        if len(raw) > min(self.max_dead_letter_bytes, self.max_record_bytes - DEAD_LETTER_MARGIN):
            headers += [(H_DLQ_SHA256, hashlib.sha256(raw).hexdigest().encode()), (H_DLQ_TRUNCATED, b"true")]
            value = b""
        robot = bound.robot if bound is not None else None
        return Outgoing.of(
            delivery,
            Record(
                kafka_topic=self.dead_letter_topic,
                key=robot.encode() if robot else None,
                value=value,
                headers=tuple(headers),
                timestamp_ms=origin.stamp_ns // 1_000_000,
                raw_value=True,
            ),
        )


def _with_raw(origin: Origin, value: Any) -> Origin:
    """``origin`` with the text of ``value`` as its raw bytes, when it has none (a dead letter of a
    value a stage made)."""
    if origin.raw is not None:
        return origin
    return replace(origin, raw=repr(value).encode("utf-8", "replace"))


def _delivery_of(bounds: Sequence[BoundMapping]) -> Delivery:
    """Dead letters of a topic travel durably if any mapping of it is ``at_least_once``."""
    if bounds and all(b.delivery == "best_effort" for b in bounds):
        return "best_effort"
    return "at_least_once"


def _ignore_schema(_fp: bytes, _text: str) -> None:
    """Default ``on_schema``: nothing to remember."""
