"""A transactional producer in native code, for the exactly-once streams.

An exactly-once batch is written in one transaction by its stream's producer, so every record
of it goes through that producer: most natively (``NativeIngest.produce``, without the GIL, as
at-least-once batches go), the few the Python path handles (diverted, dead-lettered, refused
schemas) one by one through the same producer (``produce`` / ``produce_raw`` here, the
``ingest.Sink`` a ``BatchJob`` writes to). ``begin``, ``commit`` and ``abort`` are librdkafka's
transactional calls, with the ``KafkaSink`` contract: a failure raises ``ProduceError``,
``fatal`` set when the producer was fenced or broke for good and must be made anew.
"""

from __future__ import annotations

import time
from collections.abc import Sequence

from confluent_kafka import KafkaError

from fleetlink.uplink.errors import ProduceError
from fleetlink.uplink.kafka_settings import KafkaSection, redacted
from fleetlink.uplink.native_ingest import Failures, NativeIngest
from fleetlink.uplink.producer import Delivery, DeliveryCallback, RawCallback, producer_settings


class NativeSink:
    """One transactional native producer (``start`` registers its ``transactional_id``, which
    fences any other producer holding it)."""

    def __init__(
        self, settings: KafkaSection, *, transactional_id: str, transaction_timeout_s: float
    ) -> None:
        self._settings = settings
        self._transactional_id = transactional_id
        self._timeout_s = transaction_timeout_s
        self._ingest: NativeIngest | None = None

    def start(self) -> NativeSink:
        """Create the producer and register its transactional id; raises ``ProduceError`` when
        librdkafka or the broker refuses."""
        conf = producer_settings(self._settings, self._transactional_id, self._timeout_s)
        try:
            ingest = NativeIngest(conf)
        except (RuntimeError, ValueError) as exc:
            raise ProduceError(
                f"native producer {redacted(conf)} not made: {exc}", code="_NATIVE", retriable=False
            ) from None
        self._ingest = ingest
        try:
            self._call("init", self._timeout_s)
        except ProduceError:
            self.stop(0)
            raise
        return self

    @property
    def ingest(self) -> NativeIngest:
        """The native producer, for ``NativeJob`` (raises ``ProduceError`` when not started)."""
        if self._ingest is None:
            raise ProduceError("producer not started", code="_NOT_STARTED", retriable=True)
        return self._ingest

    def stop(self, flush_timeout: float = 10.0) -> int:
        """Flush what is in flight (bounded) and close; returns records still undelivered."""
        ingest, self._ingest = self._ingest, None
        return ingest.stop(flush_timeout) if ingest is not None else 0

    # -- ingest.Sink -----------------------------------------------------------------------

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
        """Queue one record; ``on_delivery`` is called once with its delivery report."""
        began = time.monotonic()

        def done(failures: Failures) -> None:
            error = _produce_error(failures)
            on_delivery(Delivery(topic, -1, -1, error, time.monotonic() - began))

        self.ingest.produce_one(
            topic, key, value, headers=list(headers), timestamp_ms=timestamp_ms, on_done=done
        )

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
        """Queue one record; ``callback(error or None, None)`` once it is delivered (or not)."""

        def done(failures: Failures) -> None:
            callback(KafkaError(failures[0][1], failures[0][3]) if failures else None, None)

        self.ingest.produce_one(topic, key, value, headers=headers, timestamp_ms=timestamp_ms, on_done=done)

    # -- transactions ----------------------------------------------------------------------

    def begin(self) -> None:
        """Open a transaction."""
        self._call("begin", self._timeout_s)

    def commit(self, timeout_s: float) -> None:
        """Deliver what the transaction holds and commit it."""
        self._call("commit", timeout_s)

    def abort(self, timeout_s: float) -> None:
        """Abort the open transaction: read_committed consumers never see its records."""
        self._call("abort", timeout_s)

    def _call(self, op: str, timeout_s: float) -> None:
        failed = self.ingest.producer.transaction(op, timeout_s)
        if failed is not None:
            name, message, fatal, retriable, _requires_abort = failed
            raise ProduceError(f"{name}: {message}", code=name, retriable=retriable, fatal=fatal)


def _produce_error(failures: Failures) -> ProduceError | None:
    """The delivery error of a record produced alone (None: delivered)."""
    if not failures:
        return None
    _index, _code, name, message = failures[0]
    return ProduceError(f"{name}: {message}", code=name, retriable=False)
