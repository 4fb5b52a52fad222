"""One batch from an edge → Kafka records → one acknowledgement.

``BatchJob`` swaps each value's Avro single-object header for the Confluent header (the Avro
body is not touched), produces every record, and answers once every record has a delivery
report: ``ok`` when all are in Kafka or in the dead-letter topic, ``error`` when any must be
retried (the edge keeps the whole batch in its spool and sends it again).

The per-record path is kept short (thousands of records a second per uplink): the Confluent
header of each (topic, fingerprint) is made once per batch, records go to librdkafka with its
own callback (``KafkaSink.produce_raw``), and a delivery report that succeeded only counts down.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import partial
from typing import Literal, Protocol

from confluent_kafka import KafkaError, Message

from fleetlink.schemas.single_object import confluent_frame
from fleetlink.uplink.dead_letter import dead_letter
from fleetlink.uplink.diversion import Diversion
from fleetlink.uplink.errors import ProduceError
from fleetlink.uplink.producer import Delivery, RawCallback
from fleetlink.uplink.schema_ids import SchemaIds, SchemaRefusedError, SchemaUnavailableError
from fleetlink.wire import (
    SINGLE_OBJECT_MAGIC,
    Ack,
    Batch,
    Record,
    RecordFailure,
    WireError,
    split_single_object,
)

log = logging.getLogger(__name__)

_FRAME_HEAD = 5
"""Bytes of the Confluent header (magic 0 + schema id); the single-object header has 10."""


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
    ) -> None:
        """Hand one record to Kafka; ``on_delivery`` is called once with its delivery report."""

    def produce_raw(
        self,
        topic: str,
        key: bytes | None,
        value: bytes,
        *,
        headers: list[tuple[str, bytes]],
        timestamp_ms: int,
        callback: RawCallback,
    ) -> None:
        """Hand one record to Kafka with librdkafka's own delivery ``callback`` (the per-record fast path)."""


@dataclass
class IngestStats:
    """Batch and record counters of the ingest, shared by threads (change them under ``lock``)."""

    batches: int = 0
    batches_ok: int = 0
    batches_failed: int = 0
    records: int = 0
    dead_lettered: int = 0
    lock: threading.Lock = field(default_factory=threading.Lock, repr=False)


def count_outcome(stats: IngestStats, status: str) -> None:
    """Count a batch answered ``status``."""
    with stats.lock:
        if status == "ok":
            stats.batches_ok += 1
        else:
            stats.batches_failed += 1


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
        diversion: Diversion | None = None,
        counted: bool = True,
        dead: Mapping[int, str] | None = None,
        on_retry: Callable[[], None] | None = None,
    ) -> None:
        self._batch = batch
        self._on_retry = on_retry
        """Called when a record is settled for a retry (the batch will be answered ``error``):
        at once, so that the stream's later batches can wait for this one (``stream_fence``)."""
        self._dead_seqs = dead or {}
        """Seqs to send to the dead-letter topic without producing them (why, by seq): records
        Kafka refused for good in an exactly-once transaction that had to be aborted."""
        self._counted = counted
        """False for a part of a batch (``native_ingest``): the whole batch is counted there."""
        self._diversion = diversion
        """Records of topics the policy does not let out as they are (``uplink.diversion``)."""
        self._sink = sink
        self._ids = schema_ids
        self._dlq = dead_letter_topic
        self._dlq_max = dead_letter_max_bytes
        self._on_delivery = on_delivery
        self._on_done = on_done
        self._stats = stats
        self._lock = threading.Lock()
        self._remaining = len(batch.records)
        self._retry: list[RecordFailure] = []
        self._dead: list[RecordFailure] = []
        self._produced_at = 0.0

    def run(self) -> None:
        """Produce every record (Confluent-framed, diverted or dead-lettered); ``on_done`` hears the ack
        once all are settled."""
        records = self._batch.records
        if self._counted:
            with self._stats.lock:
                self._stats.batches += 1
                self._stats.records += len(records)
        if not records:
            self._finish()
            return
        self._produced_at = time.monotonic()
        produce = self._sink.produce_raw
        report = self._report
        heads: dict[tuple[str, bytes], bytes] = {}
        unavailable: dict[tuple[str, bytes], str] = {}  # the registry failed once: not again per record
        elsewhere = self._elsewhere if self._dead_seqs or self._diversion is not None else None
        for index, record in enumerate(records):
            topic, value = record.kafka_topic, record.value
            if elsewhere is not None and elsewhere(record):
                continue
            if not record.raw_value:
                head = heads.get((topic, value[2:10])) if value[:2] == SINGLE_OBJECT_MAGIC else None
                if head is None:
                    failed = unavailable.get((topic, value[2:10]))
                    if failed is not None:
                        self._settle(record, retry=failed)
                        continue
                    try:
                        value = self._kafka_value(record)
                    except SchemaUnavailableError as exc:
                        unavailable[topic, record.value[2:10]] = str(exc)
                        self._settle(record, retry=str(exc))
                        continue
                    except (SchemaRefusedError, WireError) as exc:
                        self._dead_letter(record, stage="register", reason=str(exc))
                        continue
                    heads[topic, record.value[2:10]] = value[:_FRAME_HEAD]
                else:
                    value = head + value[10:]
            try:
                produce(
                    topic,
                    record.key,
                    value,
                    headers=list(record.headers),
                    timestamp_ms=record.timestamp_ms,
                    callback=partial(report, index),
                )
            except ProduceError as exc:
                self._failed(record, exc)
            except Exception as exc:  # noqa: BLE001 - an unexpected producer error: the edge retries the batch
                self._settle(record, retry=f"produce failed: {exc}")

    # -- per record ------------------------------------------------------------------------

    def _elsewhere(self, record: Record) -> bool:
        """Whether ``record`` goes anywhere but its topic (and sends it there): the dead-letter
        topic unproduced (``dead``), or where the policy diverts its topic."""
        reason = self._dead_seqs.get(record.seq)
        if reason is not None:
            self._dead_letter(record, stage="produce", reason=reason)
            return True
        diversion = self._diversion
        if diversion is not None and record.kafka_topic in diversion.routes:
            diversion.handle(record, self._settle)
            return True
        return False

    def _kafka_value(self, record: Record) -> bytes:
        fingerprint, body = split_single_object(record.value)
        batch = self._batch
        schema_id = self._ids.id_for(batch.site, record.kafka_topic, fingerprint, batch.schemas)
        return confluent_frame(schema_id, bytes(body))

    def _report(self, index: int, error: KafkaError | None, _msg: Message | None) -> None:
        """librdkafka's delivery report for record ``index`` (on the producer's poll thread)."""
        record = self._batch.records[index]
        if self._on_delivery is not None:
            self._on_delivery(record.kafka_topic, error is None, time.monotonic() - self._produced_at)
        if error is None:
            with self._lock:
                self._remaining -= 1
                done = self._remaining == 0
            if done:
                self._finish()
            return
        self._failed(
            record,
            ProduceError(
                f"{error.name()}: {error.str()}", code=error.name(), retriable=bool(error.retriable())
            ),
        )

    def _failed(self, record: Record, error: ProduceError) -> None:
        if error.retriable or error.code.startswith("_"):
            self._settle(record, retry=str(error))
        else:
            self._dead_letter(record, stage="produce", reason=str(error))

    def _dead_letter(self, record: Record, *, stage: str, reason: str) -> None:
        if record.kafka_topic == self._dlq:
            # the dead-letter record itself cannot be written: keep it at the edge, say why
            self._settle(record, retry=f"dead-letter topic refused the record: {reason}")
            return
        dl = dead_letter(
            dlq_topic=self._dlq,
            stage=stage,
            reason=reason,
            intended_topic=record.kafka_topic,
            key=record.key,
            raw=record.value,
            headers=record.headers,
            timestamp_ms=record.timestamp_ms,
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
            self._sink.produce(
                dl.topic,
                dl.key,
                dl.value,
                headers=dl.headers,
                timestamp_ms=dl.timestamp_ms,
                on_delivery=on_dlq,
            )
        except Exception as exc:  # noqa: BLE001 - keep the batch at the edge
            self._settle(record, retry=f"{reason}; dead-letter write failed: {exc}")

    def _settle(self, record: Record, *, retry: str | None = None, dead: str | None = None) -> None:
        with self._lock:
            if retry is not None:
                self._retry.append(RecordFailure(record.seq, retry, dead_lettered=False))
            if dead is not None:
                self._dead.append(RecordFailure(record.seq, dead, dead_lettered=True))
            self._remaining -= 1
            done = self._remaining == 0
        if retry is not None and self._on_retry is not None:
            self._on_retry()
        if done:
            self._finish()

    def _finish(self) -> None:
        batch = self._batch
        failures = tuple(sorted(self._dead + self._retry, key=lambda f: f.seq))
        status: Literal["ok", "error"] = "error" if self._retry else "ok"
        detail = self._retry[0].reason if self._retry else ""
        if self._counted:
            count_outcome(self._stats, status)
        self._on_done(
            Ack(
                edge_id=batch.edge_id,
                stream=batch.stream,
                first_seq=batch.first_seq,
                last_seq=batch.last_seq,
                status=status,
                failures=failures,
                detail=detail[:1000],
            )
        )
