"""The uplink's producer against a real broker: every record gets exactly one delivery report."""

from __future__ import annotations

import threading
import uuid

import pytest

from fleetlink.uplink.errors import ProduceError
from fleetlink.uplink.kafka_settings import KafkaSection
from fleetlink.uplink.producer import Delivery, KafkaSink


def test_every_record_gets_one_successful_report(kafka_bootstrap: str) -> None:
    topic = f"fleetlink.uplink.producer.{uuid.uuid4().hex[:8]}"
    reports: list[Delivery] = []
    done = threading.Event()

    def on_delivery(d: Delivery) -> None:
        reports.append(d)
        if len(reports) == 500:
            done.set()

    with KafkaSink(KafkaSection(bootstrap_servers=kafka_bootstrap)) as sink:
        for i in range(500):
            sink.produce(
                topic,
                f"tb4_{i % 5:02d}".encode(),
                b"v%d" % i,
                headers=[("seq", b"%d" % i)],
                timestamp_ms=1_700_000_000_000 + i,
                on_delivery=on_delivery,
            )
        assert done.wait(30)
    assert all(d.error is None for d in reports)
    assert sorted(d.offset for d in reports) == list(range(500))


def test_oversized_record_is_reported_not_raised(kafka_bootstrap: str) -> None:
    topic = f"fleetlink.uplink.producer.big.{uuid.uuid4().hex[:8]}"
    reports: list[Delivery] = []
    got = threading.Event()

    def on_delivery(d: Delivery) -> None:
        reports.append(d)
        got.set()

    settings = KafkaSection(bootstrap_servers=kafka_bootstrap, message_max_bytes=10_000)
    with KafkaSink(settings) as sink:
        sink.produce(topic, b"k", b"x" * 50_000, on_delivery=on_delivery)
        assert got.wait(10)
    assert len(reports) == 1
    error = reports[0].error
    assert error is not None
    assert error.code == "MSG_SIZE_TOO_LARGE"
    assert not error.retriable


def test_a_fenced_transactional_producer_stops_without_raising(kafka_bootstrap: str) -> None:
    """A producer another one fenced has failed for good: its commit says so, and stopping it
    (the uplink drops it and takes the stream over) reports what stayed undelivered, not raises."""
    topic = f"fleetlink.uplink.producer.fenced.{uuid.uuid4().hex[:8]}"
    settings = KafkaSection(bootstrap_servers=kafka_bootstrap)
    txn_id = f"fenced-{uuid.uuid4().hex[:8]}"
    stale = KafkaSink(settings, transactional_id=txn_id, transaction_timeout_s=20).start()
    stale.begin()
    stale.produce(topic, b"k", b"stale", on_delivery=lambda _d: None)
    newer = KafkaSink(settings, transactional_id=txn_id, transaction_timeout_s=20).start()
    try:
        with pytest.raises(ProduceError) as failed:
            stale.commit(20)
        assert failed.value.fatal
        assert stale.stop(0) >= 0
    finally:
        newer.stop(0)
