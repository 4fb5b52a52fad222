"""One batch from an edge → Kafka records → one acknowledgement.

``BatchJob`` swaps each value's Avro single-object header for the Confluent header (the Avro
body is not touched), produces every record, and answers once every record has a delivery
report: ``ok`` when all are in Kafka or in the dead-letter topic, ``error`` when any must be
retried (the edge keeps the whole batch in its spool and sends it again).
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import Literal, Protocol

from fleetlink.wan import Ack, Batch, Record, RecordFailure, WireError, split_single_object
from schemas.single_object import confluent_frame
from uplink.dead_letter import dead_letter
from uplink.producer import Delivery
from uplink.schema_ids import SchemaIds, SchemaRefusedError, SchemaUnavailableError

log = logging.getLogger(__name__)


class Sink(Protocol):
    """What a batch job needs from Kafka (``uplink.producer.KafkaSink`` provides it)."""

    def produce(
        self,
        topic: str,
        key: bytes | None,
        value: bytes,
        *,
        headers: Sequence[tuple[str, bytes]] = (),
        timestamp_ms: int = 0,
        on_delivery: Callable[[Delivery], None],
    ) -> None: ...


@dataclass
class IngestStats:
    batches: int = 0
    batches_ok: int = 0
    batches_failed: int = 0
    records: int = 0
    dead_lettered: int = 0
    lock: threading.Lock = field(default_factory=threading.Lock, repr=False)


@dataclass
class _Pending:
    remaining: int
    retry: list[RecordFailure] = field(default_factory=list)
    dead: list[RecordFailure] = field(default_factory=list)
    lock: threading.Lock = field(default_factory=threading.Lock)


class BatchJob:
    """Produce one batch; ``on_done(ack)`` is called once, when every record is settled."""

    def __init__(
        self,
        batch: Batch,
        *,
        sink: Sink,
        schema_ids: SchemaIds,
        dead_letter_topic: str,
        on_done: Callable[[Ack], None],
        stats: IngestStats,
        dead_letter_max_bytes: int = 900_000,
        on_delivery: Callable[[str, bool, float], None] | None = None,
    ) -> None:
        self._batch = batch
        self._sink = sink
        self._ids = schema_ids
        self._dlq = dead_letter_topic
        self._dlq_max = dead_letter_max_bytes
        self._on_delivery = on_delivery
        self._on_done = on_done
        self._stats = stats
        self._pending = _Pending(remaining=len(batch.records))

    def run(self) -> None:
        with self._stats.lock:
            self._stats.batches += 1
            self._stats.records += len(self._batch.records)
        if not self._batch.records:
            self._finish()
            return
        for record in self._batch.records:
            self._produce(record)

    # -- per record ------------------------------------------------------------------------

    def _produce(self, record: Record) -> None:
        try:
            value = self._kafka_value(record)
        except SchemaUnavailableError as exc:
            self._settle(record, retry=str(exc))
            return
        except (SchemaRefusedError, WireError) as exc:
            self._dead_letter(record, stage="register", reason=str(exc))
            return
        try:
            self._sink.produce(
                record.kafka_topic, record.key, value, headers=list(record.headers),
                timestamp_ms=record.timestamp_ms,
                on_delivery=partial(self._delivered, record),
            )
        except Exception as exc:  # noqa: BLE001 - a fatal producer error: the edge retries the batch
            self._settle(record, retry=f"produce failed: {exc}")

    def _kafka_value(self, record: Record) -> bytes:
        if record.raw_value:
            return record.value
        fingerprint, body = split_single_object(record.value)
        schema_id = self._ids.id_for(record.kafka_topic, fingerprint, self._batch.schemas)
        return confluent_frame(schema_id, bytes(body))

    def _delivered(self, record: Record, delivery: Delivery) -> None:
        error = delivery.error
        if self._on_delivery is not None:
            self._on_delivery(delivery.topic, error is None, delivery.latency_s)
        if error is None:
            self._settle(record)
        elif error.retriable or error.code.startswith("_"):
            self._settle(record, retry=str(error))
        else:
            self._dead_letter(record, stage="produce", reason=str(error))

    def _dead_letter(self, record: Record, *, stage: str, reason: str) -> None:
        if record.kafka_topic == self._dlq:
            # the dead-letter record itself cannot be written: keep it at the edge, say why
            self._settle(record, retry=f"dead-letter topic refused the record: {reason}")
            return
        dl = dead_letter(
            dlq_topic=self._dlq, stage=stage, reason=reason, intended_topic=record.kafka_topic,
            key=record.key, raw=record.value, headers=record.headers, timestamp_ms=record.timestamp_ms,
            max_value_bytes=self._dlq_max,
        )

        def on_dlq(delivery: Delivery) -> None:
            if delivery.error is None:
                with self._stats.lock:
                    self._stats.dead_lettered += 1
                self._settle(record, dead=reason)
            else:
                self._settle(record, retry=f"{reason}; dead-letter write failed: {delivery.error}")

        try:
            self._sink.produce(dl.topic, dl.key, dl.value, headers=dl.headers,
                               timestamp_ms=dl.timestamp_ms, on_delivery=on_dlq)
        except Exception as exc:  # noqa: BLE001 - keep the batch at the edge
            self._settle(record, retry=f"{reason}; dead-letter write failed: {exc}")

    def _settle(self, record: Record, *, retry: str | None = None, dead: str | None = None) -> None:
        pending = self._pending
        with pending.lock:
            if retry is not None:
                pending.retry.append(RecordFailure(record.seq, retry, dead_lettered=False))
            if dead is not None:
                pending.dead.append(RecordFailure(record.seq, dead, dead_lettered=True))
            pending.remaining -= 1
            done = pending.remaining == 0
        if done:
            self._finish()

    def _finish(self) -> None:
        batch, pending = self._batch, self._pending
        failures = tuple(sorted(pending.dead + pending.retry, key=lambda f: f.seq))
        status: Literal["ok", "error"] = "error" if pending.retry else "ok"
        detail = pending.retry[0].reason if pending.retry else ""
        with self._stats.lock:
            if status == "ok":
                self._stats.batches_ok += 1
            else:
                self._stats.batches_failed += 1
        self._on_done(Ack(
            edge_id=batch.edge_id, stream=batch.stream, first_seq=batch.first_seq,
            last_seq=batch.last_seq, status=status, failures=failures, detail=detail[:1000],
        ))
