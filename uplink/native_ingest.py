"""The uplink's per-record path in native code: a batch into Kafka with its decisions per tail.

``ScannedBatch.scan`` parses a batch's record groups once. Everything the uplink decides — the
sender's identity, the topic policy, the schema ids — depends on a record's Kafka topic, its
schema fingerprint and its sender headers, never on its key: it is decided here, in Python, per
distinct topic, on a view of the batch with one record per (topic, sender headers) (``view``).
A batch from 200 robots on five topics is five decisions, not a thousand. ``NativeProducer``
then hands every record of an approved topic to librdkafka (the same library confluent-kafka
loaded, with the same settings: idempotent, ``acks=all``) without the GIL and counts its
delivery reports. Records of other topics (diverted by the policy, a schema the registry
refused or could not give, raw dead letters of an internal topic) and records whose delivery
failed go through the Python path (``ingest.BatchJob``), which makes the same records, dead
letters and retries it always did. One ack answers the whole batch once every part is settled.
Records of one topic may then be on two producers, which Kafka does not order one against the
other: the stream's next batch waits (``ordered.Gate``) until the Python part is settled.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from fleetlink._native import NativeProducer, ScannedBatch
from fleetlink.schemas.single_object import confluent_frame
from fleetlink.uplink.ingest import BatchJob, IngestStats, Sink, count_outcome
from fleetlink.uplink.ordered import Gate
from fleetlink.uplink.policy import Decision
from fleetlink.uplink.schema_ids import SchemaIds, SchemaRefusedError, SchemaUnavailableError
from fleetlink.wire import Ack, Batch, Record, RecordFailure, WireError, decode_payload
from fleetlink.wire.robot_events import IDENTITY_HEADERS

log = logging.getLogger(__name__)

Failures = list[tuple[int, int, str, str]]
"""``(record index, librdkafka error code, name, message)`` of records whose delivery failed."""


def librdkafka_path() -> str | None:
    """Where the librdkafka confluent-kafka loaded lives (``None`` when it is not found)."""
    import confluent_kafka  # noqa: F401 - loads librdkafka into the process

    try:
        maps = Path("/proc/self/maps").read_text()
    except OSError:
        return None
    for line in maps.splitlines():
        path = line.split()[-1] if line.split() else ""
        if "librdkafka" in Path(path).name:
            return path
    return None


class NativeIngest:
    """One native producer and the thread that hands each finished batch to its callback."""

    def __init__(self, producer_config: Mapping[str, Any]) -> None:
        path = librdkafka_path()
        if path is None:
            raise RuntimeError("librdkafka is not loaded in this process")
        settings = [(key, _text(value)) for key, value in producer_config.items() if not callable(value)]
        self.producer = NativeProducer(path, settings)
        self._jobs: dict[int, Callable[[Failures], None]] = {}
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="uplink-native-done", daemon=True)
        self._thread.start()

    def produce(
        self,
        scanned: ScannedBatch,
        topics: list[int],
        heads: dict[tuple[int, bytes], bytes],
        on_done: Callable[[Failures], None],
        *,
        min_seq: int = 0,
    ) -> list[int]:
        """Produce the records of ``topics`` (ids of ``scanned.topics()``) whose schema has a
        Confluent header in ``heads`` and whose seq is above ``min_seq``; ``on_done(failures)``
        once they are delivered (at once when there is none). Returns the indices of the
        records left to the caller (none at or below ``min_seq``)."""
        with self._lock:  # the batch id is registered before its first report can arrive
            batch_id, produced, others = self.producer.produce(scanned, topics, heads, min_seq)
            if produced:
                self._jobs[batch_id] = on_done
        if not produced:
            on_done([])
        return others

    def produce_one(
        self,
        topic: str,
        key: bytes | None,
        value: bytes,
        *,
        headers: list[tuple[str, bytes]],
        timestamp_ms: int,
        on_done: Callable[[Failures], None],
    ) -> None:
        """Produce one record; ``on_done(failures)`` once it is delivered (or not)."""
        with self._lock:
            batch_id = self.producer.produce_one(topic, key, value, headers, timestamp_ms)
            self._jobs[batch_id] = on_done

    def _run(self) -> None:
        while not self._stop.is_set():
            for batch_id, failures in self.producer.wait_done(0.5):
                with self._lock:
                    callback = self._jobs.pop(batch_id, None)
                if callback is not None:
                    try:
                        callback(failures)
                    except Exception as exc:  # noqa: BLE001 - one batch's bookkeeping must not stop the others
                        log.error("native ingest: finishing batch %d failed: %r", batch_id, exc)

    def stop(self, flush_timeout: float = 10.0) -> int:
        """Deliver what is in flight (bounded), then close; returns records not delivered."""
        left = self.producer.flush(flush_timeout)
        self.producer.close()
        self._stop.set()
        self._thread.join(5)
        return left


def _text(value: object) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    return str(value)


def view(head: Batch, scanned: ScannedBatch) -> Batch:
    """The batch as the admission checks read it: one record per distinct (topic, sender
    headers), carrying the seq of its first record and only those headers."""
    topics = scanned.topics()
    records = tuple(
        Record(topics[topic][0], None, b"", tuple(headers), seq=seq)
        for topic, headers, seq in scanned.senders(list(IDENTITY_HEADERS))
    )
    return dataclasses.replace(head, records=records)


@dataclasses.dataclass
class _Parts:
    waiting: int
    retry: list[RecordFailure] = dataclasses.field(default_factory=list)
    dead: list[RecordFailure] = dataclasses.field(default_factory=list)


class NativeJob:
    """One batch: approved tails natively, the rest (and delivery failures) by ``BatchJob``."""

    def __init__(
        self,
        head: Batch,
        scanned: ScannedBatch,
        *,
        native: NativeIngest,
        sink: Sink,
        schema_ids: SchemaIds,
        routes: Mapping[str, Decision],
        job: Callable[..., BatchJob],
        on_done: Callable[[Ack], None],
        stats: IngestStats,
        on_delivery: Callable[[str, bool, float], None] | None = None,
        min_seq: int = 0,
        counted: bool = True,
    ) -> None:
        """``min_seq``: records at or below it are not produced (an exactly-once stream's that
        Kafka has); ``counted`` False: the caller counts the batch in ``stats``."""
        self._head = head
        self._min_seq = min_seq
        self._counted = counted
        self._scanned = scanned
        self._native = native
        self._sink = sink
        self._ids = schema_ids
        self._routes = routes
        self._job = job
        """Makes the ``BatchJob`` of a part: ``job(batch, on_done=...)``."""
        self._on_done = on_done
        self._stats = stats
        self._on_delivery = on_delivery
        self._parts = _Parts(waiting=2)  # the native part and the Python part
        self._lock = threading.Lock()
        self._produced_topics: list[int] = []
        self._produced_at = 0.0

    def run(self) -> Gate | None:
        """Produce natively the records of topics whose schema ids are at hand, the rest through a
        ``BatchJob``; ``on_done`` hears one ack once both parts are settled. When the ``BatchJob``
        part holds records of a topic the next batches produce natively (its schema id was not at
        hand) and is not settled yet, returns a ``Gate`` that opens once it is: Kafka does not
        order two producers, so the stream's next batch must not overtake them."""
        if self._counted:
            with self._stats.lock:
                self._stats.batches += 1
                self._stats.records += len(self._scanned)
        topics: list[int] = []
        heads: dict[tuple[int, bytes], bytes] = {}
        unresolved = False
        for index, (topic, _count, _raw, fps) in enumerate(self._scanned.topics()):
            if topic in self._routes:
                continue  # diverted or refused by the policy: the Python path knows how
            try:
                for fp in fps:
                    schema_id = self._ids.id_for(self._head.site, topic, fp, self._head.schemas)
                    heads[index, fp] = confluent_frame(schema_id, b"")
            except (SchemaUnavailableError, SchemaRefusedError, WireError):
                unresolved = True
                continue  # the Python path retries or dead-letters these records, record by record
            topics.append(index)
        self._produced_topics = topics
        self._produced_at = time.monotonic()
        others = self._native.produce(self._scanned, topics, heads, self._native_done, min_seq=self._min_seq)
        if not unresolved:  # diverted or raw records only: the next batch sends those the same way
            self._python_part(others, self._part_done)
            return None
        gate = Gate()

        def settled(ack: Ack) -> None:
            try:
                self._part_done(ack)
            finally:
                gate.open()

        try:
            self._python_part(others, settled)
        except BaseException:
            gate.open()
            raise
        return gate

    def _python_part(self, indices: list[int], on_done: Callable[[Ack], None]) -> None:
        if not indices:
            on_done(self._ack((), "ok", ""))
            return
        records = []
        for index in indices:
            seq, payload = self._scanned.record(index)
            records.append(decode_payload(payload, seq))
        part = dataclasses.replace(self._head, records=tuple(records), first_seq=records[0].seq)
        self._job(part, on_done=on_done).run()

    def _native_done(self, failures: Failures) -> None:
        if self._on_delivery is not None:
            self._report_deliveries(failures)
        if not failures:
            self._part_done(self._ack((), "ok", ""))
            return
        log.info(
            "native ingest: %d record(s) of batch %s/%s %d.. not delivered (%s): sent again the Python way",
            len(failures),
            self._head.edge_id,
            self._head.stream,
            self._head.first_seq,
            failures[0][2],
        )
        self._python_part(sorted(index for index, *_ in failures), self._part_done)

    def _report_deliveries(self, failures: Failures) -> None:
        """One delivery report per record produced natively (only when metrics are exported)."""
        on_delivery = self._on_delivery
        if on_delivery is None:
            return
        latency = time.monotonic() - self._produced_at
        failed = [index for index, *_ in failures]
        counts = self._scanned.delivery_counts(self._produced_topics, failed, self._min_seq)
        for topic, delivered, undelivered in counts:
            for _ in range(delivered):
                on_delivery(topic, True, latency)
            for _ in range(undelivered):
                on_delivery(topic, False, latency)

    def _part_done(self, ack: Ack) -> None:
        with self._lock:
            parts = self._parts
            for failure in ack.failures:
                (parts.dead if failure.dead_lettered else parts.retry).append(failure)
            if ack.status == "error" and all(f.dead_lettered for f in ack.failures):
                parts.retry.append(RecordFailure(self._head.first_seq, ack.detail or "not produced", False))
            parts.waiting -= 1
            finished = parts.waiting == 0
        if finished:
            status = "error" if parts.retry else "ok"
            detail = parts.retry[0].reason if parts.retry else ""
            if self._counted:
                count_outcome(self._stats, status)
            self._on_done(
                self._ack(tuple(sorted(parts.dead + parts.retry, key=lambda f: f.seq)), status, detail)
            )

    def _ack(self, failures: tuple[RecordFailure, ...], status: str, detail: str) -> Ack:
        return Ack(
            edge_id=self._head.edge_id,
            stream=self._head.stream,
            first_seq=self._head.first_seq,
            last_seq=self._scanned.last_seq() if len(self._scanned) else self._head.first_seq,
            status="error" if status == "error" else "ok",
            failures=failures,
            detail=detail[:1000],
        )
