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
from fleetlink.uplink.batch_writes import DeliveryTally, Done, ack_when_written, refuse, wait_written
from fleetlink.uplink.commands.ownership import Owner
from fleetlink.uplink.commands.status_checks import check_status
from fleetlink.uplink.commands.status_records import STATUS_SCHEMA, status_value
from fleetlink.uplink.ingest import Sink
from fleetlink.wire.commands import StatusAck, StatusEvent, decode_status_batch, encode_status_ack
from fleetlink.wire.errors import EnvelopeError

log = logging.getLogger(__name__)

STATUS_KEY = "fleetlink/*/command-status/*"


class Registry(Protocol):
    """The schema registry call the status writer makes."""

    def register(self, subject: str, schema: dict[str, Any]) -> int:
        """Register ``schema`` under ``subject`` (or find it there); returns the schema id."""


class StatusWriter:
    """Writes command status events to the status topic, keyed by robot, registering its schema once."""

    def __init__(self, sink: Sink, registry: Registry, topic: str) -> None:
        self._sink = sink
        self._registry = registry
        self.topic = topic
        self._schema_id: int | None = None
        self._lock = threading.Lock()
        self.written = 0

    def schema_id(self) -> int:
        """The registry id of the status schema, registered under the topic's subject on first use
        (``RegistryError`` when that fails)."""
        with self._lock:
            if self._schema_id is None:
                self._schema_id = self._registry.register(subject_for_topic(self.topic), STATUS_SCHEMA)
            return self._schema_id

    def write(self, events: Sequence[StatusEvent], done: Done) -> None:
        """Produce ``events``; ``done`` once with None when Kafka has them all, else the first problem."""
        if not events:
            done(None)
            return
        try:
            schema_id = self.schema_id()
        except RegistryError as exc:
            done(f"cannot register the status schema: {exc}")
            return
        tally = DeliveryTally(len(events), done, self._count_written)
        for event in events:
            try:
                self._sink.produce(
                    self.topic,
                    event.robot.encode(),
                    status_value(schema_id, event),
                    timestamp_ms=event.at_ms,
                    on_delivery=tally.delivered,
                )
            except Exception as exc:  # noqa: BLE001 - a fatal producer error fails this batch only
                tally.failed(self.topic, exc)

    def _count_written(self) -> None:
        self.written += 1

    def write_and_wait(self, events: Sequence[StatusEvent], timeout: float = 60.0) -> str | None:
        """Produce ``events`` and wait up to ``timeout`` seconds: None when Kafka has them all, else the
        problem."""
        return wait_written(lambda done: self.write(events, done), timeout, "status")


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
        """Take a repeater's status batch: refuse it when malformed or naming another site, answer a
        heartbeat at once, else write the events it may report and answer once Kafka has them."""
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
            refuse(query, str(exc))
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
            refuse(query, f"refused: {checked.problem}")
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

        done = ack_when_written(
            query,
            count,
            lambda problem: self._limiter.log(
                logging.WARNING,
                "status-write",
                "status batch from %s not written: %s",
                batch.repeater,
                problem,
            ),
        )

        if not events:
            done(None)
            return
        self._writer.write(events, done)
