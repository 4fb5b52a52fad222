"""Outcomes of calls -> Kafka records on the mappings' topics; and the queryable that takes the
repeaters' outcome batches (``fleetlink/*/call-outcome/*``) and answers once Kafka has them.

A batch's site is the one of its key (routers let a site query only under its own keys): a
batch naming another site is refused whole, outcomes about a robot another site holds or for a
mapping this uplink does not have are dropped (counted).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any, Protocol

import zenoh

from fleetlink.common.ratelimit import LogLimiter
from fleetlink.schemas.errors import RegistryError, SchemaError
from fleetlink.schemas.registry import subject_for_topic
from fleetlink.schemas.single_object import confluent_frame
from fleetlink.uplink.batch_writes import DeliveryTally, Done, ack_when_written, refuse, wait_written
from fleetlink.uplink.calls.convert import CallTypes
from fleetlink.uplink.calls.mapping import ActionMapping, ServiceMapping
from fleetlink.uplink.calls.plan import CORRELATION_HEADER, GOAL_HEADER
from fleetlink.uplink.calls.records import RecordWriter, record_schema
from fleetlink.uplink.commands.ownership import Owner
from fleetlink.uplink.ingest import Sink
from fleetlink.wire.calls import Outcome, OutcomeBatch, decode_outcomes
from fleetlink.wire.errors import EnvelopeError

log = logging.getLogger(__name__)

OUTCOME_KEY = "fleetlink/*/call-outcome/*"


class Registry(Protocol):
    """The schema registry call the outcome writer makes."""

    def register(self, subject: str, schema: dict[str, Any]) -> int:
        """Register ``schema`` under ``subject`` (or find it there); returns the schema id."""


@dataclass(frozen=True)
class _Target:
    topic: str
    writer: RecordWriter
    typename: str
    """The ROS type of the wrapped value (``…_Response``, ``…_Feedback``, ``…_Result``)."""
    ros_name: str
    """The mapping's ``to`` template."""


def _ns(typename: str, kind: str) -> tuple[str, str]:
    pkg, _, name = typename.split("/")
    suffix = {"reply": "Reply", "feedback": "Feedback", "result": "Goal"}[kind]
    area = "services" if kind == "reply" else "actions"
    return f"{name}{suffix}", f"fleetlink.{area}.{pkg}"


class OutcomeWriter:
    """Writes call outcomes to their mappings' Kafka topics (Avro, Confluent wire format), registering each
    topic's schema once."""

    def __init__(
        self,
        sink: Sink,
        registry: Registry,
        types: CallTypes,
        services: Sequence[ServiceMapping],
        actions: Sequence[ActionMapping],
    ) -> None:
        self._sink = sink
        self._registry = registry
        self._types = types
        self._lock = threading.Lock()
        self._ids: dict[str, int] = {}
        self._targets: dict[tuple[str, str], _Target] = {}
        self._services = {m.name: m for m in services}
        self._actions = {m.name: m for m in actions}
        self.written = 0
        self.dropped = 0

    def knows(self, out: Outcome) -> bool:
        """Whether this uplink has the service (for a reply) or action mapping ``out`` names."""
        return out.mapping in (self._services if out.kind == "reply" else self._actions)

    def _target(self, out: Outcome) -> _Target:
        kind = "result" if out.kind == "cancel" else out.kind
        with self._lock:
            target = self._targets.get((out.mapping, kind))
        if target is not None:
            return target
        if kind == "reply":
            service = self._services[out.mapping]
            topic, typename, to = service.reply_to, f"{service.type}_Response", service.to
            base = service.type
        else:
            action = self._actions[out.mapping]
            base, to = action.type, action.to
            topic = action.feedback_to if kind == "feedback" else action.result_to
            typename = f"{action.type}_{'Feedback' if kind == 'feedback' else 'Result'}"
        name, namespace = _ns(base, kind)
        schema = record_schema(kind, self._types.codec(typename).schema, name, namespace)
        target = _Target(topic, RecordWriter(kind, schema), typename, to)
        with self._lock:
            self._targets[(out.mapping, kind)] = target
        return target

    def _schema_id(self, target: _Target) -> int:
        with self._lock:
            known = self._ids.get(target.topic)
        if known is not None:
            return known
        schema_id = self._registry.register(subject_for_topic(target.topic), target.writer.schema)
        with self._lock:
            self._ids[target.topic] = schema_id
        return schema_id

    def record(self, out: Outcome) -> tuple[str, bytes, bytes, list[tuple[str, bytes]]]:
        """(topic, key, the Avro value without its Confluent frame, headers) of one outcome."""
        target = self._target(out)
        status, detail, body = out.status, out.detail, None
        if out.payload is not None:
            try:
                body = self._types.to_avro(target.typename, out.payload)
            except SchemaError as exc:
                status = "error" if out.kind != "feedback" else status
                detail = f"the robot's answer is no {target.typename}: {exc}"
                if out.kind == "feedback":
                    raise
        name = target.ros_name.replace("{robot}", out.robot)
        if out.kind == "reply":
            head: dict[str, Any] = {"correlation_id": out.call_id, "robot": out.robot, "service": name}
        else:
            head = {"goal_id": out.call_id, "robot": out.robot, "action": name}
        if out.kind != "feedback":
            head.update(
                status=status, detail=detail[:2000], requested_at=out.issued_at_ms or out.at_ms, site=out.site
            )
        head["at"] = out.at_ms
        value = target.writer.value(head, body)
        key = out.robot if out.kind == "reply" else out.call_id
        header = CORRELATION_HEADER if out.kind == "reply" else GOAL_HEADER
        return target.topic, key.encode(), value, [(header, out.call_id.encode())]

    def write(self, outcomes: Sequence[Outcome], done: Done) -> None:
        """Produce every outcome; ``done`` once with None when Kafka has them all, else the first problem."""
        records = []
        for out in outcomes:
            if not self.knows(out):
                self.dropped += 1
                continue
            try:
                topic, key, value, headers = self.record(out)
                schema_id = self._schema_id(self._target(out))
            except RegistryError as exc:
                done(f"cannot register the schema of {out.mapping}'s topic: {exc}")
                return
            except SchemaError as exc:
                log.warning("dropped %s outcome of %s: %s", out.kind, out.call_id, exc)
                self.dropped += 1
                continue
            records.append((topic, key, confluent_frame(schema_id, value), headers, out.at_ms))
        if not records:
            done(None)
            return
        tally = DeliveryTally(len(records), done, self._count_written)
        for topic, key, value, headers, at_ms in records:
            try:
                self._sink.produce(
                    topic, key, value, headers=headers, timestamp_ms=at_ms, on_delivery=tally.delivered
                )
            except Exception as exc:  # noqa: BLE001 - a fatal producer error fails this batch only
                tally.failed(topic, exc)

    def _count_written(self) -> None:
        self.written += 1

    def write_and_wait(self, outcomes: Sequence[Outcome], timeout: float = 60.0) -> str | None:
        """Produce ``outcomes`` and wait up to ``timeout`` seconds: None when Kafka has them all, else the
        problem."""
        return wait_written(lambda done: self.write(outcomes, done), timeout, "outcome")


def site_of_outcome_key(key: str) -> str | None:
    """The site of a ``fleetlink/<site>/call-outcome/<repeater>`` key, or None for any other key."""
    parts = key.split("/")
    if len(parts) == 4 and parts[0] == "fleetlink" and parts[2] == "call-outcome":
        return parts[1]
    return None


def check_outcomes(
    key: str, batch: OutcomeBatch, owner_of: Callable[[str], Owner | None]
) -> tuple[list[Outcome], int, str | None]:
    """(kept outcomes with the key's site, dropped count, why the batch is refused)."""
    site = site_of_outcome_key(key)
    if site is None:
        return [], 0, f"{key!r} is not an outcome key"
    if batch.site != site:
        return [], 0, f"the batch says site {batch.site!r} but arrived on site {site!r}'s key"
    kept = []
    for out in batch.outcomes:
        owner = owner_of(out.robot)
        if owner is not None and owner.site != site:
            continue
        kept.append(replace(out, site=site))
    return kept, len(batch.outcomes) - len(kept), None


class OutcomeIntake:
    """The queryable on ``fleetlink/*/call-outcome/*``."""

    def __init__(self, writer: OutcomeWriter, *, owner_of: Callable[[str], Owner | None]) -> None:
        self._writer = writer
        self._owner_of = owner_of
        self._limiter = LogLimiter(log)
        self.batches = 0
        self.refused = 0
        self.dropped = 0

    def on_query(self, query: zenoh.Query) -> None:
        """Take a repeater's outcome batch: refuse it when malformed or naming another site, else write the
        outcomes it may report and answer once Kafka has them."""
        payload = query.payload
        try:
            if payload is None:
                raise EnvelopeError("outcome batch", "the query carries no payload")
            batch = decode_outcomes(payload.to_bytes())
        except EnvelopeError as exc:
            self._limiter.log(
                logging.WARNING, "bad", "refused a malformed outcome batch on %s: %s", query.key_expr, exc
            )
            refuse(query, str(exc))
            return
        kept, dropped, problem = check_outcomes(str(query.key_expr), batch, self._owner_of)
        if problem is not None:
            self.refused += 1
            self._limiter.log(
                logging.WARNING, "forged", "refused an outcome batch on %s: %s", query.key_expr, problem
            )
            refuse(query, f"refused: {problem}")
            return
        self.dropped += dropped
        self.batches += 1
        count = len(batch.outcomes)

        done = ack_when_written(
            query,
            count,
            lambda problem: self._limiter.log(
                logging.WARNING, "write", "outcomes from %s not written: %s", batch.repeater, problem
            ),
        )

        self._writer.write(kept, done)
