"""Status events -> records on the command status topic, keyed by robot; and the queryable that
takes the repeaters' status batches (and heartbeats) and answers once Kafka has them."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Sequence
from typing import Any, Protocol

import zenoh

from fleetlink.common.ratelimit import LogLimiter
from fleetlink.schemas.errors import RegistryError
from fleetlink.schemas.registry import subject_for_topic
from fleetlink.uplink.commands.ownership import Owner
from fleetlink.uplink.commands.status_checks import check_status
from fleetlink.uplink.commands.status_records import STATUS_SCHEMA, status_value
from fleetlink.uplink.errors import ProduceError
from fleetlink.uplink.ingest import Sink
from fleetlink.uplink.producer import Delivery
from fleetlink.wire.commands import StatusAck, StatusEvent, decode_status_batch, encode_status_ack
from fleetlink.wire.errors import EnvelopeError

log = logging.getLogger(__name__)

STATUS_KEY = "fleetlink/*/command-status/*"
Done = Callable[[str | None], None]
"""Called once with None when every record is in Kafka, else with the first problem."""


class Registry(Protocol):
    def register(self, subject: str, schema: dict[str, Any]) -> int: ...


class StatusWriter:
    def __init__(self, sink: Sink, registry: Registry, topic: str) -> None:
        self._sink = sink
        self._registry = registry
        self.topic = topic
        self._schema_id: int | None = None
        self._lock = threading.Lock()
        self.written = 0

    def schema_id(self) -> int:
        with self._lock:
            if self._schema_id is None:
                self._schema_id = self._registry.register(subject_for_topic(self.topic), STATUS_SCHEMA)
            return self._schema_id

    def write(self, events: Sequence[StatusEvent], done: Done) -> None:
        if not events:
            done(None)
            return
        try:
            schema_id = self.schema_id()
        except RegistryError as exc:
            done(f"cannot register the status schema: {exc}")
            return
        left = [len(events)]
        problems: list[str] = []
        lock = threading.Lock()

        def delivered(report: Delivery) -> None:
            with lock:
                if report.error is not None:
                    problems.append(str(report.error))
                else:
                    self.written += 1
                left[0] -= 1
                finished = left[0] == 0
            if finished:
                done(problems[0] if problems else None)

        for event in events:
            try:
                self._sink.produce(
                    self.topic,
                    event.robot.encode(),
                    status_value(schema_id, event),
                    timestamp_ms=event.at_ms,
                    on_delivery=delivered,
                )
            except Exception as exc:  # noqa: BLE001 - a fatal producer error fails this batch only
                failure = ProduceError(f"produce failed: {exc}", code="_PRODUCE", retriable=True)
                delivered(Delivery(self.topic, -1, -1, failure, 0.0))

    def write_and_wait(self, events: Sequence[StatusEvent], timeout: float = 60.0) -> str | None:
        finished = threading.Event()
        outcome: list[str | None] = []

        def done(problem: str | None) -> None:
            outcome.append(problem)
            finished.set()

        self.write(events, done)
        if not finished.wait(timeout):
            return "Kafka did not acknowledge the status records in time"
        return outcome[0]


class StatusIntake:
    """The queryable on ``fleetlink/*/command-status/*``."""

    def __init__(self, writer: StatusWriter, *, owner_of: Callable[[str], Owner | None]) -> None:
        self._writer = writer
        self._owner_of = owner_of
        self._limiter = LogLimiter(log)
        self.batches = 0
        self.heartbeats = 0
        self.refused = 0
        """Status batches naming another site than their key's."""
        self.dropped = 0
        """Status events about a robot another site holds."""

    def on_query(self, query: zenoh.Query) -> None:
        payload = query.payload
        try:
            if payload is None:
                raise EnvelopeError("status batch", "the query carries no payload")
            batch = decode_status_batch(payload.to_bytes())
        except EnvelopeError as exc:
            self._limiter.log(
                logging.WARNING,
                "bad-status",
                "refused a malformed status batch on %s: %s",
                query.key_expr,
                exc,
            )
            query.reply_err(str(exc).encode())
            query.drop()
            return
        checked = check_status(str(query.key_expr), batch, self._owner_of)
        if checked.problem is not None:
            self.refused += 1
            self._limiter.log(
                logging.WARNING,
                "forged-status",
                "refused a status batch on %s: %s",
                query.key_expr,
                checked.problem,
            )
            query.reply_err(f"refused: {checked.problem}".encode())
            query.drop()
            return
        if checked.dropped:
            self.dropped += checked.dropped
            self._limiter.log(
                logging.WARNING,
                "foreign-status",
                "dropped %d status event(s) on %s about robots another site holds",
                checked.dropped,
                query.key_expr,
            )
        if not batch.events:
            self.heartbeats += 1
            query.reply(query.key_expr, encode_status_ack(StatusAck(0)))
            query.drop()
            return
        self.batches += 1
        count = len(batch.events)
        events = checked.events

        def done(problem: str | None) -> None:
            try:
                ack = StatusAck(count) if problem is None else StatusAck(0, problem[:500])
                if problem is not None:
                    self._limiter.log(
                        logging.WARNING,
                        "status-write",
                        "status batch from %s not written: %s",
                        batch.repeater,
                        problem,
                    )
                query.reply(query.key_expr, encode_status_ack(ack))
            finally:
                query.drop()

        if not events:
            done(None)
            return
        self._writer.write(events, done)
