"""The uplink process: a Zenoh queryable for edge batches in front of a Kafka producer.

Edges send each batch as a Zenoh query on ``fleetlink/<site>/ingest/<edge_id>``; the uplink
answers with an ``Ack`` only when Kafka has acknowledged (or dead-lettered) every record.
Several uplinks may serve the same sites: a query reaches one of them, and each also serves the
keys addressed to it by name (``.../via/<uplink id>``), which edges probe to share the load
(``edge.runtime.uplinks``). Nothing is kept on disk here: an unanswered batch stays in the
edge's spool and comes again.
"""

from __future__ import annotations

import dataclasses
import gc
import logging
import threading
import time
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from functools import partial
from types import TracebackType
from typing import Any, Protocol

import zenoh

from fleetlink._native import ScannedBatch
from fleetlink.common.metrics import (
    CounterDeltas,
    NullMetrics,
    PrometheusMetrics,
    serve_metrics,
    split_listen,
)
from fleetlink.common.metrics.server import HttpServer
from fleetlink.common.ratelimit import LogLimiter
from fleetlink.common.zenoh_options import ZenohOptions
from fleetlink.schemas.registry import SchemaRegistry
from fleetlink.uplink.admission import Admission, Refused
from fleetlink.uplink.calls.convert import load_call_types
from fleetlink.uplink.commands.decode import CommandDecoder
from fleetlink.uplink.commands.directory import RobotDirectory
from fleetlink.uplink.commands.registrations import RegistrationsReader
from fleetlink.uplink.commands.router import CommandRouter
from fleetlink.uplink.config import UplinkConfig
from fleetlink.uplink.delivery_board import DeliveryBoard, acked_scanned, acked_topics
from fleetlink.uplink.delivery_status import DeliveryStatus
from fleetlink.uplink.diversion import Diversion
from fleetlink.uplink.exactly_once import ExactlyOnceWriter, MarksReader, Pending, TxnSink, above, at_or_below
from fleetlink.uplink.exactly_once.writer import ExactlyOnceStats
from fleetlink.uplink.identity import Source, source_of
from fleetlink.uplink.ingest import BatchJob, IngestStats, count_outcome
from fleetlink.uplink.kafka_check import check_kafka_access
from fleetlink.uplink.latency import DeliveryLatency
from fleetlink.uplink.native_ingest import NativeIngest, NativeJob, view
from fleetlink.uplink.native_sink import NativeSink
from fleetlink.uplink.ordered import Gate, KeyedSerialExecutor
from fleetlink.uplink.policy import Decision, InternalTopics, TopicPolicy
from fleetlink.uplink.producer import KafkaSink
from fleetlink.uplink.refusals import Refusals
from fleetlink.uplink.registration_records import RegistrationWriter
from fleetlink.uplink.schema_ids import SchemaIds
from fleetlink.uplink.stream_fence import StreamFence
from fleetlink.uplink.topics import ensure_topics
from fleetlink.wire import Ack, AckStatus, Batch, WireError, decode_batch, decode_batch_head, encode_ack
from fleetlink.wire.batch import peek_stream
from fleetlink.wire.keys import VIA, via_key

log = logging.getLogger(__name__)


class UplinkExtension(Protocol):
    """Something run beside the uplink on its session (the fleet console), started and stopped with it."""

    def start(self) -> object:
        """Start the extension, once the uplink has started; what it returns is ignored."""

    def stop(self) -> None:
        """Stop the extension, before the uplink closes its queryables and its Zenoh session."""


class Uplink:
    """The uplink service: edge batches to Kafka, commands and calls to the sites, delivery figures to
    consoles."""

    def __init__(
        self,
        config: UplinkConfig,
        zenoh_options: ZenohOptions | None = None,
        *,
        metrics: PrometheusMetrics | None = None,
        extensions: Sequence[Callable[[Uplink], UplinkExtension]] = (),
    ) -> None:
        self.config = config
        # Without a metrics endpoint nobody can read them: counting every delivery report would
        # cost some 3-5 us a record (a third of the uplink's work per record) for nothing.
        self.metrics: PrometheusMetrics | NullMetrics = (
            metrics
            if metrics is not None
            else PrometheusMetrics("uplink")
            if config.metrics is not None
            else NullMetrics()
        )
        self._metrics_server: HttpServer | None = None
        self._registry_deltas = CounterDeltas()
        self._gc_before: tuple[int, int, int] | None = None
        self._zenoh_options = zenoh_options or config.zenoh.options()
        self.stats = IngestStats()
        self._session: zenoh.Session | None = None
        self._queryables: list[Any] = []
        self._sink: KafkaSink | None = None
        self._native: NativeIngest | None = None
        self._registry: SchemaRegistry | None = None
        self._ids: SchemaIds | None = None
        self._pool: ThreadPoolExecutor | None = None
        self._serial: KeyedSerialExecutor | None = None
        self._commands: CommandRouter | None = None
        self._admission: Admission | None = None
        self._registrations: RegistrationWriter | None = None
        self._reader: RegistrationsReader | None = None
        self.directory = RobotDirectory(release_after_ms=round(config.ownership.release_after * 1000))
        """Which site holds each robot: read from the registrations topic, claimed at ingest."""
        self.delivery_latency = DeliveryLatency()
        """Per site: from a batch's arrival to Kafka's last delivery report (shown by the console)."""
        self.delivery = DeliveryBoard()
        """Per site: batches answered, records Kafka acknowledged per topic, dead letters."""
        self._delivery_status = DeliveryStatus(config.id, self.delivery, self.delivery_latency)
        self.extension_factories = tuple(extensions)
        """Made and started at the end of ``start`` (the layer above passes the fleet console)."""
        self.extensions: list[UplinkExtension] = []
        self._slots = threading.BoundedSemaphore(config.ingest.max_concurrent_batches)
        self._fence = StreamFence()
        """At-least-once streams whose batch failed: their later batches wait for it (order)."""
        self._limiter = LogLimiter(log)
        # a dead letter must itself fit: keep room for its headers below the producer's limit
        self._dlq_max = max(1_000, config.kafka.message_max_bytes - 64 * 1024)
        self._max_record_bytes = config.kafka.max_record_bytes()
        """Told to the edges in every acknowledgement: they keep larger records off the WAN."""
        self._eo_lock = threading.Lock()
        self._eo_writer: ExactlyOnceWriter | None = None
        self._marks: MarksReader | None = None
        self.refusals = Refusals(
            self.metrics, refused_topic=config.topics.refused, max_value_bytes=self._dlq_max
        )
        """What was refused from each source (batches whole, records to the refused topic)."""

    # -- lifecycle -------------------------------------------------------------------------

    def start(self) -> Uplink:
        """Check Kafka access and create missing topics, start the registry client, registrations reader
        and producers, serve edge batches on the Zenoh session, then the command router, metrics and
        extensions as configured; returns self."""
        cfg = self.config
        call_types = load_call_types(cfg)  # before any socket: a missing type names its YAML path
        check_kafka_access(cfg.kafka)
        ensure_topics(cfg.kafka, cfg.topics)
        self._registry = SchemaRegistry(cfg.registry.url)
        self._registry.start()
        self._ids = SchemaIds(self._registry, compatibility=cfg.registry.compatibility)
        self._admission = Admission(_policy(cfg), self._ids)
        self._reader = RegistrationsReader(
            cfg.kafka, cfg.topics.registrations, CommandDecoder(self._registry), self.directory
        ).start()
        self._registrations = RegistrationWriter(self._registry, cfg.topics.registrations, self.directory)
        self._sink = KafkaSink(cfg.kafka).start()
        if cfg.ingest.native:
            try:
                self._native = NativeIngest(cfg.kafka.producer_config())
            except (RuntimeError, ValueError) as exc:
                log.warning("the native ingest path cannot start (%s); every record goes through Python", exc)
        self._pool = ThreadPoolExecutor(max_workers=4, thread_name_prefix="uplink-batch")
        self._serial = KeyedSerialExecutor(self._pool)
        self._session = zenoh.open(self._zenoh_options.to_config())
        for site in cfg.ingest.sites:
            key = f"fleetlink/{site}/ingest/*"
            for served in (key, via_key(key, cfg.id)):  # any uplink's, and this one's by name
                self._queryables.append(
                    self._session.declare_queryable(served, self._on_query, complete=True)
                )
            log.info("serving edge batches on %s and %s", key, via_key(key, cfg.id))
        self._delivery_status.start(self._session)
        if cfg.commands or cfg.services or cfg.actions:
            self._commands = CommandRouter(
                cfg,
                session=self._session,
                sink=self._sink,
                registry=self._registry,
                directory=self.directory,
                call_types=call_types,
            ).start()
        if cfg.metrics is not None and isinstance(self.metrics, PrometheusMetrics):
            host, port = split_listen(cfg.metrics.listen)
            self._metrics_server = serve_metrics(host, port, self.metrics, refresh=self._refresh_metrics)
        for make in self.extension_factories:
            extension = make(self)
            extension.start()
            self.extensions.append(extension)
        # what start made lives as long as the service: out of full collections; young ones rarer
        # (deliveries and records never form cycles): 90 ms of collections for 60,000 records before
        self._gc_before = gc.get_threshold()
        gc.freeze()
        gc.set_threshold(50_000, 20, 100)
        return self

    def stop(self) -> None:
        """Stop everything ``start`` started: extensions, queryables, command router and reader, batch
        workers, producers (flushed, bounded), the Zenoh session and the registry client."""
        if self._gc_before is not None:
            gc.set_threshold(*self._gc_before)
            gc.unfreeze()
            self._gc_before = None
        if self._metrics_server is not None:
            self._metrics_server.stop()
            self._metrics_server = None
        for extension in self.extensions:
            extension.stop()
        self.extensions = []
        for queryable in self._queryables:
            queryable.undeclare()
        self._queryables.clear()
        self._delivery_status.stop()
        if self._commands is not None:
            self._commands.stop()
            self._commands = None
        if self._reader is not None:
            self._reader.stop()
            self._reader = None
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=False)
            self._pool = None
        if self._eo_writer is not None:
            self._eo_writer.stop()
            self._eo_writer = None
        if self._marks is not None:
            self._marks.stop()
            self._marks = None
        self._stop_producers()
        if self._session is not None:
            self._session.close()
            self._session = None
        if self._registry is not None:
            self._registry.stop()
            self._registry = None

    def _stop_producers(self) -> None:
        left = 0
        if self._native is not None:
            left += self._native.stop()
            self._native = None
        if self._sink is not None:
            left += self._sink.stop()
            self._sink = None
        if left:
            log.warning("%d records were still unacknowledged by Kafka at stop; their edges resend", left)

    def __enter__(self) -> Uplink:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    def _refresh_metrics(self) -> None:
        """Before a scrape: the registry's failures and the command lag (pull model)."""
        if self._ids is not None:
            for reason, total in self._ids.error_totals().items():
                self.metrics.on_registry_error(reason, self._registry_deltas.delta(reason, total))
        router = self._commands
        self.metrics.set_command_lag(router.lag_s() if router is not None else 0.0)

    @property
    def metrics_url(self) -> str | None:
        """Where ``/metrics`` and ``/health`` are served, when configured."""
        return self._metrics_server.url if self._metrics_server is not None else None

    @property
    def session(self) -> zenoh.Session:
        """The uplink's Zenoh session (once started)."""
        if self._session is None:
            raise RuntimeError("the uplink is not started")
        return self._session

    @property
    def commands(self) -> CommandRouter | None:
        """The command router (None when no command mappings are configured or not started)."""
        return self._commands

    # -- batches ---------------------------------------------------------------------------

    def _on_query(self, query: zenoh.Query) -> None:
        """On a Zenoh thread: take the bytes and return. Decoding and producing run on a worker,
        the batches of one edge in arrival order (a robot's records keep their order with
        several batches in flight); the Zenoh thread never waits for the GIL-heavy part. An
        edge's probe (``.../via/*``) is answered on this uplink's own key, empty."""
        key = str(query.key_expr)
        if key.endswith(f"/{VIA}/*"):
            query.reply(via_key(key[: -len(f"/{VIA}/*")], self.config.id), b"")
            query.drop()
            return
        payload = query.payload
        if payload is None:
            query.reply_err(b"empty query: a batch is expected as the payload")
            query.drop()
            return
        serial = self._serial
        if serial is None:
            query.reply_err(b"uplink stopping")
            query.drop()
            return
        if not self._slots.acquire(blocking=False):
            self.metrics.on_ingested(site_of(key), "refused", 0)
            self._hold_back_after(key, payload.to_bytes())
            query.reply_err(b"uplink busy: retry later")
            query.drop()
            return
        # an edge's batches in order, whichever of its keys they came on
        serial.submit(
            key.split(f"/{VIA}/", maxsplit=1)[0],
            partial(self._ingest, query, payload.to_bytes(), time.monotonic()),
        )

    def _hold_back_after(self, key: str, data: bytes) -> None:
        """A batch answered busy, unread: its at-least-once stream's later batches must not reach
        Kafka before it comes again (``stream_fence``). Read from the start of the batch only, and
        only for a stream of the edge whose key it came on."""
        source, head = source_of(key), peek_stream(data)
        if source is None or head is None or head.origin:
            return
        if (head.site, head.edge_id) == (source.site, source.edge_id):
            self._fence.failed((head.site, head.edge_id, head.stream), head.first_seq, evict=False)

    def _answered(self, batch: Batch, scanned: ScannedBatch | None, ack: Ack, arrived: float) -> None:
        """Count a batch's answer: metrics, the site's delivery figures, a warning on errors."""
        dead = {f.seq for f in ack.failures if f.dead_lettered}
        records = len(scanned) if scanned is not None else len(batch.records)
        self.metrics.on_ingested(batch.site, ack.status, records, len(dead))
        if ack.status == "ok":
            self.delivery_latency.observe(batch.site, time.monotonic() - arrived)
            acked = acked_scanned(scanned, dead) if scanned is not None else acked_topics(batch.records, dead)
            self.delivery.on_batch(batch.site, "ok", acked, len(dead))
        else:
            self.delivery.on_batch(batch.site, ack.status)
        if ack.status == "error":
            self._limiter.log(
                logging.WARNING,
                "batch-error",
                "batch %s/%s %d..%d not fully delivered: %s",
                ack.edge_id,
                ack.stream,
                ack.first_seq,
                ack.last_seq,
                ack.detail,
            )

    def _ingest(self, query: zenoh.Query, data: bytes, arrived: float) -> Gate | None:
        """On a worker: decode the batch and produce it; the reply comes with the last delivery report."""
        scanned: ScannedBatch | None = None
        try:
            if self._native is not None:
                parsed = decode_batch_head(data)
                try:
                    scanned = ScannedBatch.scan(parsed.body, parsed.groups_at)
                    batch = view(parsed.head, scanned)
                except ValueError:
                    batch = decode_batch(data)  # says exactly what is wrong (WireError)
                    scanned = None
            else:
                batch = decode_batch(data)
        except WireError as exc:
            self._limiter.log(
                logging.ERROR, "bad-batch", "refused a malformed batch on %s: %s", str(query.key_expr), exc
            )
            self.metrics.on_ingested(site_of(str(query.key_expr)), "refused", 0)
            self._finish(query, error=f"malformed batch: {exc}")
            return None
        ids, admission = self._ids, self._admission
        if ids is None or admission is None:
            self._finish(query, error="uplink stopping")
            return None
        # -- who sent it, what it may write (uplink.admission): per batch, per distinct topic --
        key = str(query.key_expr)
        source = source_of(key)
        verdict = (
            Refused("identity", "not an ingest key") if source is None else admission.check(source, batch)
        )
        if isinstance(verdict, Refused):
            self.refusals.batch(source, key, verdict.reason, verdict.detail)
            self.metrics.on_ingested(site_of(key), "refused", 0)
            self.delivery.on_batch(site_of(key), "refused")
            self._finish(query, error=f"refused ({verdict.reason}): {verdict.detail}")
            return None
        # ---------------------------------------------------------------------------------------
        missing = ids.unknown(batch.site, batch.elided) if batch.elided else ()
        if missing:  # before anything is produced: the edge sends the batch again, with them
            self._ask_for_schemas(query, batch, scanned, missing)
            return None
        if batch.origin:  # the edge asks for exactly-once delivery
            self._write_exactly_once(
                query, data, batch, scanned, source=verdict.source, routes=verdict.routes, arrived=arrived
            )
            return None
        return self._write_at_least_once(
            query, batch, scanned, source=verdict.source, routes=verdict.routes, arrived=arrived
        )

    def _ask_for_schemas(
        self, query: zenoh.Query, batch: Batch, scanned: ScannedBatch | None, missing: tuple[bytes, ...]
    ) -> None:
        """Answer ``need_schemas``: the batch left out schemas this uplink does not know."""
        if not batch.origin:  # the stream's later batches wait for this one (order)
            self._fence.failed((batch.site, batch.edge_id, batch.stream), batch.first_seq)
        log.info(
            "batch %s/%s %d..%d leaves out %d schema(s) this uplink does not know: asking for them",
            batch.edge_id,
            batch.stream,
            batch.first_seq,
            scanned.last_seq() if scanned is not None else batch.last_seq,
            len(missing),
        )
        detail = "send the batch again with these schemas"
        self._send_back(query, batch, scanned, "need_schemas", detail=detail, missing=missing)

    def _send_back(
        self,
        query: zenoh.Query,
        batch: Batch,
        scanned: ScannedBatch | None,
        status: AckStatus,
        *,
        detail: str,
        missing: tuple[bytes, ...] = (),
    ) -> None:
        """Answer a batch of which nothing was produced: it is to come again (``status``)."""
        self.metrics.on_ingested(batch.site, status, 0)
        last_seq = scanned.last_seq() if scanned is not None else batch.last_seq
        ack = Ack(
            batch.edge_id,
            batch.stream,
            batch.first_seq,
            last_seq,
            status,
            detail=detail,
            missing_schemas=missing,
        )
        self._finish(query, ack)

    def _write_at_least_once(
        self,
        query: zenoh.Query,
        batch: Batch,
        scanned: ScannedBatch | None,
        *,
        source: Source,
        routes: Mapping[str, Decision],
        arrived: float,
    ) -> Gate | None:
        """Produce an admitted at-least-once batch, unless an earlier batch of its stream failed
        (``stream_fence``: then it is answered ``held_back`` and comes again after that one). Returns
        the ``Gate`` the stream's next batch waits for, if it must wait (``NativeJob.run``)."""
        sink, ids, registrations = self._sink, self._ids, self._registrations
        if sink is None or ids is None or registrations is None:
            self._finish(query, error="uplink stopping")
            return None
        stream = (batch.site, batch.edge_id, batch.stream)
        fenced = self._fence.check(stream, batch.first_seq, arrived)
        if fenced is not None:
            detail = f"batch {fenced.failed_seq}.. of this stream was not produced: it goes first"
            self._send_back(query, batch, scanned, "held_back", detail=detail)
            return None
        on_retry = partial(self._fence.failed, stream, batch.first_seq)

        def done(ack: Ack) -> None:
            if ack.status == "error":
                on_retry()
            self._answered(batch, scanned, ack, arrived)
            self._finish(query, ack)

        metered = not isinstance(self.metrics, NullMetrics)
        on_delivery = self.metrics.on_delivered if metered else None
        job = partial(
            BatchJob,
            sink=sink,
            schema_ids=ids,
            dead_letter_topic=self.config.topics.dead_letter,
            stats=self.stats,
            dead_letter_max_bytes=self._dlq_max,
            on_delivery=on_delivery,
            diversion=(
                Diversion(source, routes, sink=sink, refusals=self.refusals, registrations=registrations)
                if routes
                else None
            ),
            on_retry=on_retry,
        )
        native = self._native
        if scanned is None or native is None:
            job(batch, on_done=done).run()
            return None
        return NativeJob(
            batch,
            scanned,
            native=native,
            sink=sink,
            schema_ids=ids,
            routes=routes,
            job=partial(job, counted=False),
            on_done=done,
            stats=self.stats,
            on_delivery=on_delivery,
        ).run()

    def _write_exactly_once(
        self,
        query: zenoh.Query,
        data: bytes,
        batch: Batch,
        scanned: ScannedBatch | None,
        *,
        source: Source,
        routes: Mapping[str, Decision],
        arrived: float,
    ) -> None:
        """Hand an exactly-once batch to its stream's writer, which answers the edge once the
        transaction holding it committed (or not). With ``scanned`` (the native path) ``batch``
        is its view; without, the decoded batch."""
        sink, ids, registrations = self._sink, self._ids, self._registrations
        if sink is None or ids is None or registrations is None:
            self._finish(query, error="uplink stopping")
            return
        metered = not isinstance(self.metrics, NullMetrics)
        on_delivery = self.metrics.on_delivered if metered else None

        def run(txn: TxnSink, after: int, dead: dict[int, str], done: Callable[[Ack], None]) -> None:
            diversion = (
                Diversion(source, routes, sink=txn, refusals=self.refusals, registrations=registrations)
                if routes
                else None
            )
            job = partial(
                BatchJob,
                sink=txn,
                schema_ids=ids,
                dead_letter_topic=self.config.topics.dead_letter,
                stats=self.stats,
                dead_letter_max_bytes=self._dlq_max,
                on_delivery=on_delivery,
                diversion=diversion,
                counted=False,
                dead=dead,
            )
            if scanned is not None and isinstance(txn, NativeSink) and not dead:
                NativeJob(
                    batch,
                    scanned,
                    native=txn.ingest,
                    sink=txn,
                    schema_ids=ids,
                    routes=routes,
                    job=job,
                    on_done=done,
                    stats=self.stats,
                    on_delivery=on_delivery,
                    min_seq=after,
                    counted=False,
                ).run()
                return
            job(above(batch if scanned is None else decode_batch(data), after), on_done=done).run()

        def answer(ack: Ack) -> None:
            count_outcome(self.stats, ack.status)
            self._answered(batch, scanned, ack, arrived)
            self._finish(query, ack)

        pending = (
            Pending(batch, scanned.last_seq(), scanned.at_or_below)
            if scanned is not None
            else Pending(batch, batch.last_seq, at_or_below(batch))
        )
        try:
            writer = self._exactly_once()
        except Exception as exc:  # noqa: BLE001 - the marks topic's reader could not start: answer, retry later
            self._limiter.log(logging.ERROR, "exactly-once", "exactly-once writer not ready: %s", exc)
            self._finish(query, error=f"exactly-once writer not ready: {exc}")
            return
        with self.stats.lock:
            self.stats.batches += 1
            self.stats.records += len(scanned) if scanned is not None else len(batch.records)
        writer.submit(pending, run, answer)

    def _exactly_once(self) -> ExactlyOnceWriter:
        """The writer of exactly-once batches, made (and the marks topic read) on first use."""
        with self._eo_lock:
            if self._eo_writer is None:
                cfg = self.config
                self._marks = MarksReader(cfg.kafka, cfg.topics.marks, f"fleetlink-marks-{cfg.id}").start()
                native = self._native is not None

                def make_sink(transactional_id: str) -> TxnSink:
                    kind = NativeSink if native else KafkaSink
                    return kind(
                        cfg.kafka,
                        transactional_id=transactional_id,
                        transaction_timeout_s=cfg.exactly_once.transaction_timeout,
                    )

                self._eo_writer = ExactlyOnceWriter(
                    make_sink,
                    marks=self._marks,
                    marks_topic=cfg.topics.marks,
                    prefix=cfg.exactly_once.transactional_id_prefix,
                    transaction_timeout_s=cfg.exactly_once.transaction_timeout,
                    idle_close_s=cfg.exactly_once.idle_close,
                )
            return self._eo_writer

    @property
    def exactly_once_stats(self) -> ExactlyOnceStats | None:
        """What the exactly-once path did (None: no exactly-once batch came yet)."""
        writer = self._eo_writer
        return writer.stats if writer is not None else None

    def _finish(self, query: zenoh.Query, ack: Ack | None = None, *, error: str = "") -> None:
        """Answer a batch taken by ``_on_query`` (its ack, or ``error``) and free its slot."""
        self._slots.release()
        try:
            if ack is not None:
                ack = dataclasses.replace(ack, max_record_bytes=self._max_record_bytes)
                query.reply(query.key_expr, encode_ack(ack))
            else:
                query.reply_err(error.encode())
        finally:
            query.drop()


def site_of(key: str) -> str:
    """The site of an ingest key ``fleetlink/<site>/ingest/<edge_id>`` (``?`` if it is not one)."""
    source = source_of(key)
    return source.site if source is not None else "?"


def _policy(cfg: UplinkConfig) -> TopicPolicy:
    topics = cfg.topics
    owned = {topics.command_dead_letter, topics.command_status, topics.refused}
    owned.update(mapping.from_ for mapping in cfg.commands)
    for service in cfg.services:
        owned.update((service.from_, service.reply_to))
    for action in cfg.actions:
        owned.update((action.from_, action.feedback_to, action.result_to))
        if action.cancel_from is not None:
            owned.add(action.cancel_from)
    owned.update((topics.audit, topics.marks))
    internal = InternalTopics(topics.registrations, topics.dead_letter, frozenset(owned))
    return TopicPolicy(cfg.policy.patterns(), cfg.policy.default.topics, internal)
