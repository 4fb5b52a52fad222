"""Two uplinks on one exactly-once stream, against real Kafka: the one that takes it over fences the
other, whose open transaction is aborted and whose next commit fails; no record is ever written twice."""

from __future__ import annotations

import threading
import uuid
from collections.abc import Iterator

import pytest
from confluent_kafka.admin import AdminClient, NewTopic

from fleetlink.uplink.exactly_once import ExactlyOnceWriter, MarksReader
from fleetlink.uplink.kafka_settings import KafkaSection
from fleetlink.uplink.producer import Delivery, KafkaSink
from fleetlink.wire import Ack, Batch, Record
from tests.integration.test_uplink_exactly_once import committed_values, values

ORIGIN = 77


def batch(topic: str, seqs: range) -> Batch:
    records = tuple(Record(topic, b"r", f"v{s}".encode(), raw_value=True, seq=s) for s in seqs)
    return Batch("fence-site", "edge", "durable", seqs.start, records, origin=ORIGIN)


def produce_all(part: Batch, sink: KafkaSink, _dead: dict[int, str]) -> Ack:
    """What the uplink's batch job does, reduced to producing every record and waiting."""
    left = len(part.records)
    lock, done = threading.Lock(), threading.Event()

    def delivered(_d: Delivery) -> None:
        nonlocal left
        with lock:
            left -= 1
            if left == 0:
                done.set()

    for r in part.records:
        sink.produce(r.kafka_topic, r.key, r.value, on_delivery=delivered)
    assert done.wait(20)
    return Ack(part.edge_id, part.stream, part.first_seq, part.last_seq, "ok")


@pytest.fixture
def topics(kafka_bootstrap: str) -> tuple[str, str]:
    tag = uuid.uuid4().hex[:8]
    data, marks = f"fence.{tag}", f"fence.marks.{tag}"
    admin = AdminClient({"bootstrap.servers": kafka_bootstrap})
    for future in admin.create_topics([NewTopic(t, 1, 1) for t in (data, marks)]).values():
        future.result(30)
    return data, marks


@pytest.fixture
def writers(kafka_bootstrap: str, topics: tuple[str, str]) -> Iterator[list[ExactlyOnceWriter]]:
    kafka = KafkaSection(bootstrap_servers=kafka_bootstrap)
    prefix = f"fence{uuid.uuid4().hex[:6]}"
    out, readers = [], []
    for n in range(2):
        reader = MarksReader(kafka, topics[1], f"fence-{prefix}-{n}").start()
        readers.append(reader)
        out.append(
            ExactlyOnceWriter(
                kafka,
                marks=reader,
                marks_topic=topics[1],
                prefix=prefix,
                transaction_timeout_s=20,
                idle_close_s=300,
            )
        )
    yield out
    for writer in out:
        writer.stop()
    for reader in readers:
        reader.stop()


def test_uplinks_taking_turns_write_every_record_once(
    kafka_bootstrap: str, topics: tuple[str, str], writers: list[ExactlyOnceWriter]
) -> None:
    data, _marks = topics
    a, b = writers
    answers = []
    for n, start in enumerate(range(1, 400, 50)):
        writer = (a, b)[n % 2]
        part = batch(data, range(max(1, start - 20), start + 50))  # overlapping: sent again in part
        ack = writer.write(part, produce_all)
        if ack.status != "ok":  # this writer was fenced since its last batch: the edge resends
            ack = writer.write(part, produce_all)
        answers.append(ack.status)
    assert answers == ["ok"] * 8
    assert committed_values(kafka_bootstrap, data) == values(range(1, 401))
    assert a.stats.takeovers + b.stats.takeovers >= 8  # each turn fenced the other
    assert a.stats.fenced + b.stats.fenced >= 6


def test_a_fenced_uplinks_open_transaction_never_shows(
    kafka_bootstrap: str, topics: tuple[str, str], writers: list[ExactlyOnceWriter]
) -> None:
    """A is in the middle of a batch (records produced, not committed) when B takes the stream
    over: A's commit fails, A answers error, and only B's copy of those records is committed."""
    data, _marks = topics
    a, b = writers
    assert a.write(batch(data, range(1, 11)), produce_all).status == "ok"
    b_took_over = threading.Event()

    def produce_then_wait(part: Batch, sink: KafkaSink, dead: dict[int, str]) -> Ack:
        ack = produce_all(part, sink, dead)

        def take_over() -> None:
            b.write(batch(data, range(11, 31)), produce_all)
            b_took_over.set()

        threading.Thread(target=take_over).start()
        assert b_took_over.wait(30)
        return ack

    stale = a.write(batch(data, range(11, 31)), produce_then_wait)
    assert stale.status == "error"
    assert "not committed" in stale.detail
    assert committed_values(kafka_bootstrap, data) == values(range(1, 31))
    assert a.write(batch(data, range(21, 41)), produce_all).status == "ok"  # A takes it back
    assert committed_values(kafka_bootstrap, data) == values(range(1, 41))
