"""The Kafka producer adapter: every record gets a delivery report, nothing is fire-and-forget.

``KafkaSink.produce`` hands a record to librdkafka with a callback; a poll thread serves
delivery reports as they arrive. When librdkafka's queue is full the call waits (serving
reports) instead of failing, so back-pressure reaches the caller, never a silent drop.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from types import TracebackType
from typing import Any

from confluent_kafka import KafkaError, KafkaException, Message, Producer

from fleetlink.common.ratelimit import LogLimiter
from fleetlink.uplink.errors import ProduceError
from fleetlink.uplink.kafka_settings import KafkaSection, redacted

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class Delivery:
    """The outcome of one produce: ``error`` is None when Kafka acknowledged it."""

    topic: str
    partition: int
    offset: int
    error: ProduceError | None
    latency_s: float


DeliveryCallback = Callable[[Delivery], None]
RawCallback = Callable[[KafkaError | None, Message | None], None]
"""librdkafka's own delivery callback ``(error or None, message)`` (no message from the native
producer: ``uplink.native_sink``)."""


def _produce_error(err: KafkaError) -> ProduceError:
    return ProduceError(
        f"{err.name()}: {err.str()}",
        code=err.name(),
        retriable=bool(err.retriable()),
        fatal=bool(err.fatal()),
    )


def _exception_error(exc: KafkaException) -> ProduceError:
    err = exc.args[0] if exc.args and isinstance(exc.args[0], KafkaError) else None
    if err is None:
        return ProduceError(str(exc), code="_UNKNOWN", retriable=False)
    return _produce_error(err)


def producer_settings(
    settings: KafkaSection, transactional_id: str | None = None, transaction_timeout_s: float = 60.0
) -> dict[str, Any]:
    """The librdkafka settings of the uplink's producer; with ``transactional_id``, of a
    transactional one whose transactions time out after ``transaction_timeout_s``."""
    conf: dict[str, Any] = dict(settings.producer_config())
    if transactional_id is not None:
        timeout_ms = round(transaction_timeout_s * 1000)
        conf["transactional.id"] = transactional_id
        conf["transaction.timeout.ms"] = timeout_ms
        # librdkafka: a record may not outlive the transaction that holds it
        conf["delivery.timeout.ms"] = min(int(conf.get("delivery.timeout.ms", timeout_ms)), timeout_ms)
    return conf


class KafkaSink:
    """A started ``KafkaSink`` owns one idempotent producer and one thread polling it.

    With ``transactional_id`` the producer is transactional (``uplink.exactly_once``): ``start``
    also registers the id with the broker, which fences any other producer holding it, and
    records go out between ``begin`` and ``commit`` (or ``abort``).
    """

    def __init__(
        self,
        settings: KafkaSection,
        *,
        queue_wait_s: float = 30.0,
        transactional_id: str | None = None,
        transaction_timeout_s: float = 60.0,
    ) -> None:
        self._settings = settings
        self._queue_wait_s = queue_wait_s
        self._transactional_id = transactional_id
        self._transaction_timeout_s = transaction_timeout_s
        self._producer: Producer | None = None
        self._poller: threading.Thread | None = None
        self._stopping = threading.Event()
        self._fatal: ProduceError | None = None
        self._limiter = LogLimiter(log)

    # -- lifecycle -------------------------------------------------------------------------

    def start(self) -> KafkaSink:
        """Create the producer (a transactional one registers its id, fencing other holders) and start the
        poll thread; returns self. Raises ``ProduceError`` when librdkafka refuses."""
        conf = producer_settings(self._settings, self._transactional_id, self._transaction_timeout_s)
        log.info("starting Kafka producer %s", redacted(conf))
        conf["error_cb"] = self._on_client_error
        try:
            self._producer = Producer(conf)
            if self._transactional_id is not None:
                self._producer.init_transactions(self._transaction_timeout_s)
        except KafkaException as exc:
            self._producer = None
            raise _exception_error(exc) from None
        self._stopping.clear()
        self._poller = threading.Thread(target=self._poll_loop, name="kafka-poll", daemon=True)
        self._poller.start()
        return self

    def stop(self, flush_timeout: float = 10.0) -> int:
        """Flush what is in flight (bounded), stop polling; returns records still undelivered."""
        producer = self._producer
        if producer is None:
            return 0
        try:
            remaining: int = producer.flush(flush_timeout)
        except Exception as exc:  # noqa: BLE001 - failed for good (fenced), or a callback failed
            remaining = len(producer)
            self._limiter.log(logging.WARNING, "stop", "Kafka producer stopped undelivered: %s", exc)
        self._stopping.set()
        if self._poller is not None:
            self._poller.join(5)
        self._producer = None
        return remaining

    def __enter__(self) -> KafkaSink:
        return self.start()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.stop()

    # -- producing -------------------------------------------------------------------------

    def produce(
        self,
        topic: str,
        key: bytes | None,
        value: bytes,
        *,
        headers: Sequence[tuple[str, bytes]] = (),
        timestamp_ms: int = 0,
        on_delivery: DeliveryCallback,
    ) -> None:
        """Queue one record; ``on_delivery`` is called exactly once, from the poll thread.

        A record Kafka can never take (too large, illegal topic) is reported through
        ``on_delivery`` with a non-retriable error, not raised.
        """
        producer = self._producer
        if producer is None:
            raise ProduceError("producer not started", code="_NOT_STARTED", retriable=True)
        if self._fatal is not None:
            raise self._fatal
        began = time.monotonic()

        def report(err: KafkaError | None, msg: Message) -> None:
            latency = time.monotonic() - began
            error = _produce_error(err) if err is not None else None
            partition, offset = msg.partition(), msg.offset()
            on_delivery(
                Delivery(
                    topic,
                    -1 if partition is None else partition,
                    -1 if offset is None else offset,
                    error,
                    latency,
                )
            )

        deadline = began + self._queue_wait_s
        full = False
        while True:
            try:
                if full:  # serve delivery reports to make room (a fatal error surfaces here too)
                    producer.poll(0.05)
                producer.produce(
                    topic,
                    value=value,
                    key=key,
                    headers=list(headers),
                    timestamp=timestamp_ms,
                    on_delivery=report,
                )
                return
            except BufferError:
                full = True
                self._check_room(deadline)
            except KafkaException as exc:
                on_delivery(Delivery(topic, -1, -1, _exception_error(exc), time.monotonic() - began))
                return

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
        """Queue one record with librdkafka's callback, called exactly once from the poll thread
        (or from this call while it waits for room): the path for thousands of records a second,
        without a wrapper object per record.

        Raises ``ProduceError`` when the record is not queued: Kafka can never take it
        (``retriable`` False: too large, illegal topic), the producer failed fatally, or
        librdkafka's queue stayed full for ``queue_wait_s``.
        """
        producer = self._producer
        if producer is None:
            raise ProduceError("producer not started", code="_NOT_STARTED", retriable=True)
        if self._fatal is not None:
            raise self._fatal
        deadline = time.monotonic() + self._queue_wait_s
        full = False
        while True:
            try:
                if full:
                    producer.poll(0.05)
                producer.produce(
                    topic, value, key, headers=headers, timestamp=timestamp_ms, on_delivery=callback
                )
                return
            except BufferError:
                full = True
                self._check_room(deadline)
            except KafkaException as exc:
                raise _exception_error(exc) from None

    def _check_room(self, deadline: float) -> None:
        """librdkafka's queue is full: raise once it stayed full past ``deadline``."""
        if time.monotonic() > deadline:
            raise ProduceError(
                f"librdkafka queue stayed full for {self._queue_wait_s:.0f} s",
                code="_QUEUE_FULL",
                retriable=True,
            )

    def in_flight(self) -> int:
        """Records handed to librdkafka and not yet delivered."""
        return len(self._producer) if self._producer is not None else 0

    # -- transactions (a sink made with ``transactional_id``) ------------------------------

    def begin(self) -> None:
        """Open a transaction: what is produced until ``commit`` is written all or nothing. Raises
        ``ProduceError`` (``fatal`` when the producer was fenced)."""
        try:
            self._transactional().begin_transaction()
        except KafkaException as exc:
            raise _exception_error(exc) from None

    def commit(self, timeout_s: float) -> None:
        """Deliver what the transaction holds and commit it; raises ``ProduceError`` (``fatal``
        set when the producer was fenced or failed for good: it must be made anew)."""
        try:
            self._transactional().commit_transaction(timeout_s)
        except KafkaException as exc:
            raise _exception_error(exc) from None

    def abort(self, timeout_s: float) -> None:
        """Abort the open transaction: read_committed consumers never see its records."""
        try:
            self._transactional().abort_transaction(timeout_s)
        except KafkaException as exc:
            raise _exception_error(exc) from None

    def _transactional(self) -> Producer:
        producer = self._producer
        if producer is None or self._transactional_id is None:
            raise ProduceError("no transactional producer", code="_NOT_STARTED", retriable=True)
        return producer

    # -- internals -------------------------------------------------------------------------

    def _poll_loop(self) -> None:
        while not self._stopping.is_set():
            producer = self._producer
            if producer is None:
                return
            try:
                producer.poll(0.05)
            except KafkaException as exc:  # a fatal error (fenced): keep serving the failed reports
                error = _exception_error(exc)
                if self._fatal is None and error.fatal:
                    self._fatal = error
                self._limiter.log(logging.WARNING, "poll", "Kafka producer: %s", error)
            except Exception:  # a delivery callback failed: the reports after it still need serving
                log.exception("Kafka producer: a delivery report's callback failed")

    def _on_client_error(self, err: KafkaError) -> None:
        if err.fatal():
            self._fatal = _produce_error(err)
            log.error("Kafka producer fatal error: %s", err.str())
        else:
            # transient (broker down, connection refused): librdkafka retries by itself
            self._limiter.log(logging.WARNING, err.name(), "Kafka client: %s", err.str())
