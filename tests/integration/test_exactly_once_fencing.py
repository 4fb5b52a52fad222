"""Two uplinks on one exactly-once stream, against real Kafka: the one that takes it over fences the
other, whose open transaction is aborted and whose next commit fails; no record is ever written twice."""

from __future__ import annotations

import threading
import uuid
from collections.abc import Iterator

import pytest
from confluent_kafka.admin import AdminClient, NewTopic

from fleetlink.uplink.exactly_once import ExactlyOnceWriter, MarksReader, Pending, TxnSink, above, at_or_below
from fleetlink.uplink.exactly_once.writer import RunJob
from fleetlink.uplink.kafka_settings import KafkaSection
from fleetlink.uplink.native_sink import NativeSink
from fleetlink.uplink.producer import Delivery, KafkaSink
from fleetlink.wire import Ack, Batch, Record
from tests.integration.test_uplink_exactly_once import committed_values, values

ORIGIN = 77


def batch(topic: str, seqs: range) -> Batch:
    records = tuple(Record(topic, b"r", f"v{s}".encode(), raw_value=True, seq=s) for s in seqs)
    return Batch("fence-site", "edge", "durable", seqs.start, records, origin=ORIGIN)


def produce_all(part: Batch) -> RunJob:
    """What the uplink's batch job does, reduced to producing the records above the mark and waiting."""

    def run(sink: TxnSink, after: int, _dead: dict[int, str]) -> Ack:
        todo = above(part, after).records
        left = len(todo)
        lock, done = threading.Lock(), threading.Event()

        def delivered(_d: Delivery) -> None:
            nonlocal left
            with lock:
                left -= 1
                if left == 0:
                    done.set()

        for r in todo:
            sink.produce(r.kafka_topic, r.key, r.value, on_delivery=delivered)
        assert done.wait(20)
        return Ack(part.edge_id, part.stream, part.first_seq, part.last_seq, "ok")

    return run


def write(writer: ExactlyOnceWriter, part: Batch, run: RunJob | None = None) -> Ack:
    return writer.write(Pending(part, part.last_seq, at_or_below(part)), run or produce_all(part))


@pytest.fixture
def topics(kafka_bootstrap: str) -> tuple[str, str]:
    tag = uuid.uuid4().hex[:8]
    data, marks = f"fence.{tag}", f"fence.marks.{tag}"
    admin = AdminClient({"bootstrap.servers": kafka_bootstrap})
    for future in admin.create_topics([NewTopic(t, 1, 1) for t in (data, marks)]).values():
        future.result(30)
    return data, marks


@pytest.fixture(params=["python", "native"])
def writers(
    request: pytest.FixtureRequest, kafka_bootstrap: str, topics: tuple[str, str]
) -> Iterator[list[ExactlyOnceWriter]]:
    """Two uplinks' writers, with the producer the uplink uses without and with its native path."""
    kafka = KafkaSection(bootstrap_servers=kafka_bootstrap)

    def make_sink(transactional_id: str) -> TxnSink:
        if request.param == "native":
            return NativeSink(kafka, transactional_id=transactional_id, transaction_timeout_s=20)
        return KafkaSink(kafka, transactional_id=transactional_id, transaction_timeout_s=20)

    prefix = f"fence{uuid.uuid4().hex[:6]}"
    out, readers = [], []
    for n in range(2):
        reader = MarksReader(kafka, topics[1], f"fence-{prefix}-{n}").start()
        readers.append(reader)
        out.append(
            ExactlyOnceWriter(
                make_sink,
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
        ack = write(writer, part)
        if ack.status != "ok":  # this writer was fenced since its last batch: the edge resends
            ack = write(writer, part)
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
    assert write(a, batch(data, range(1, 11))).status == "ok"
    b_took_over = threading.Event()

    stale_part = batch(data, range(11, 31))

    def produce_then_wait(sink: TxnSink, after: int, dead: dict[int, str]) -> Ack:
        ack = produce_all(stale_part)(sink, after, dead)

        def take_over() -> None:
            write(b, batch(data, range(11, 31)))
            b_took_over.set()

        threading.Thread(target=take_over).start()
        assert b_took_over.wait(30)
        return ack

    stale = write(a, stale_part, produce_then_wait)
    assert stale.status == "error"
    assert "not committed" in stale.detail
    assert committed_values(kafka_bootstrap, data) == values(range(1, 31))
    assert write(a, batch(data, range(21, 41))).status == "ok"  # A takes it back
    assert committed_values(kafka_bootstrap, data) == values(range(1, 41))
