"""Two uplinks on one exactly-once stream, against real Kafka: the one that takes it over fences the
other, whose open transaction is aborted and whose next commit fails; no record is ever written twice."""

from __future__ import annotations

import threading
import uuid
from collections.abc import Callable, Iterator
from functools import partial

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


def batch(topic: str, seqs: range, acked: int = 0) -> Batch:
    records = tuple(Record(topic, b"r", f"v{s}".encode(), raw_value=True, seq=s) for s in seqs)
    return Batch("fence-site", "edge", "durable", seqs.start, records, origin=ORIGIN, acked=acked)


def produce_all(part: Batch) -> RunJob:
    """What the uplink's batch job does, reduced to producing the records above the mark."""

    def run(sink: TxnSink, after: int, _dead: dict[int, str], done: Callable[[Ack], None]) -> None:
        todo = above(part, after).records
        left = len(todo)
        lock = threading.Lock()
        ok = Ack(part.edge_id, part.stream, part.first_seq, part.last_seq, "ok")

        def delivered(_d: Delivery) -> None:
            nonlocal left
            with lock:
                left -= 1
                last = left == 0
            if last:
                done(ok)

        if not todo:
            done(ok)
        for r in todo:
            sink.produce(r.kafka_topic, r.key, r.value, on_delivery=delivered)

    return run


def failing(part: Batch) -> RunJob:
    """A batch job whose delivery fails: its transaction is aborted."""

    def run(_sink: TxnSink, _after: int, _dead: dict[int, str], done: Callable[[Ack], None]) -> None:
        done(Ack(part.edge_id, part.stream, part.first_seq, part.last_seq, "error", detail="delivery failed"))

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
    # each turn fenced the other: the batch lay beyond the mark this writer had committed, so it
    # took the stream over again (reading the other's mark) before writing, instead of failing
    assert a.stats.takeovers + b.stats.takeovers >= 8
    assert a.stats.out_of_order + b.stats.out_of_order == 0


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

    def produce_then_wait(
        sink: TxnSink, after: int, dead: dict[int, str], done: Callable[[Ack], None]
    ) -> None:
        produced: list[Ack] = []
        all_in = threading.Event()

        def produced_all(ack: Ack) -> None:
            produced.append(ack)
            all_in.set()

        produce_all(stale_part)(sink, after, dead, produced_all)
        assert all_in.wait(20)

        def take_over() -> None:
            write(b, batch(data, range(11, 31)))
            b_took_over.set()

        threading.Thread(target=take_over).start()
        assert b_took_over.wait(30)
        done(produced[0])

    stale = write(a, stale_part, produce_then_wait)
    assert stale.status == "error"
    assert "not committed" in stale.detail
    assert committed_values(kafka_bootstrap, data) == values(range(1, 31))
    assert write(a, batch(data, range(21, 41))).status == "ok"  # A takes it back
    assert committed_values(kafka_bootstrap, data) == values(range(1, 41))


def submit_all(writer: ExactlyOnceWriter, parts: list[tuple[Batch, RunJob]]) -> list[Ack]:
    """Submit batches one after the other as the uplink does and wait for every answer. The
    first batch's job waits until the others are submitted: they queue up behind its transaction."""
    answers: dict[int, Ack] = {}
    all_in, started, release = threading.Event(), threading.Event(), threading.Event()

    def answer(n: int, ack: Ack) -> None:
        answers[n] = ack
        if len(answers) == len(parts):
            all_in.set()

    def held(
        run: RunJob, sink: TxnSink, after: int, dead: dict[int, str], done: Callable[[Ack], None]
    ) -> None:
        started.set()
        assert release.wait(30)
        run(sink, after, dead, done)

    for n, (part, run) in enumerate(parts):
        job = partial(held, run) if n == 0 else run
        writer.submit(Pending(part, part.last_seq, at_or_below(part)), job, partial(answer, n))
        if n == 0:
            assert started.wait(30)  # the first batch's transaction is under way
    release.set()
    assert all_in.wait(60)
    return [answers[n] for n in range(len(parts))]


def test_batches_waiting_for_a_transaction_share_the_next_one(
    kafka_bootstrap: str, topics: tuple[str, str], writers: list[ExactlyOnceWriter]
) -> None:
    data, _marks = topics
    a, _b = writers
    parts = [batch(data, range(s, s + 10)) for s in (1, 11, 21, 31)]
    answers = submit_all(a, [(p, produce_all(p)) for p in parts])
    assert [(x.status, x.first_seq, x.last_seq) for x in answers] == [
        ("ok", 1, 10),
        ("ok", 11, 20),
        ("ok", 21, 30),
        ("ok", 31, 40),
    ]
    assert a.stats.committed == 2  # the first alone, the three that waited in one transaction
    assert committed_values(kafka_bootstrap, data) == values(range(1, 41))


def test_a_failed_batch_fails_its_whole_group_and_nothing_of_it_shows(
    kafka_bootstrap: str, topics: tuple[str, str], writers: list[ExactlyOnceWriter]
) -> None:
    data, _marks = topics
    a, _b = writers
    first = batch(data, range(1, 11))
    good, bad = batch(data, range(11, 21)), batch(data, range(21, 31))

    def refused(_sink: TxnSink, _after: int, _dead: dict[int, str], done: Callable[[Ack], None]) -> None:
        done(Ack(bad.edge_id, bad.stream, bad.first_seq, bad.last_seq, "error", (), "registry down"))

    answers = submit_all(a, [(first, produce_all(first)), (good, produce_all(good)), (bad, refused)])
    assert [x.status for x in answers] == ["ok", "error", "error"]
    assert "registry down" in answers[1].detail  # the good batch says why it was not written
    assert committed_values(kafka_bootstrap, data) == values(range(1, 11))
    again = submit_all(a, [(good, produce_all(good)), (bad, produce_all(bad))])  # the edge resends
    assert [x.status for x in again] == ["ok", "ok"]
    assert committed_values(kafka_bootstrap, data) == values(range(1, 31))


def test_a_batch_sent_behind_a_failed_one_waits_for_it(
    kafka_bootstrap: str, topics: tuple[str, str], writers: list[ExactlyOnceWriter]
) -> None:
    """Written, the later batch would move the mark past the failed one's records, and their
    resend would be skipped as already in Kafka: lost."""
    data, _marks = topics
    a, _b = writers
    assert write(a, batch(data, range(1, 11))).status == "ok"
    second = batch(data, range(11, 21), acked=10)
    third = batch(data, range(21, 31), acked=10)  # sent while the second was in flight
    assert write(a, second, failing(second)).status == "error"
    refused = write(a, third)
    assert (refused.status, refused.detail) == ("error", "out of order: seqs 11..20 not written yet")
    assert [write(a, second).status, write(a, third).status] == ["ok", "ok"]  # the edge resends in order
    assert committed_values(kafka_bootstrap, data) == values(range(1, 31))
    assert a.stats.out_of_order == 1


def test_a_stream_moving_to_another_uplink_mid_flight_keeps_every_record(
    kafka_bootstrap: str, topics: tuple[str, str], writers: list[ExactlyOnceWriter]
) -> None:
    """The edge moved the stream to ``b`` (it joined) while a batch was still on its way to
    ``a``: ``b`` takes the stream over but writes nothing past the records not yet written."""
    data, _marks = topics
    a, b = writers
    assert write(a, batch(data, range(1, 11))).status == "ok"
    still_at_a = batch(data, range(11, 21), acked=10)
    sent_to_b = batch(data, range(21, 31), acked=10)
    refused = write(b, sent_to_b)
    assert (refused.status, refused.detail) == ("error", "out of order: seqs 11..20 not written yet")
    assert write(a, still_at_a).status == "error"  # fenced when b took the stream over
    assert [write(b, still_at_a).status, write(b, sent_to_b).status] == ["ok", "ok"]
    assert committed_values(kafka_bootstrap, data) == values(range(1, 31))


def test_seqs_the_edge_settled_are_no_gap(
    kafka_bootstrap: str, topics: tuple[str, str], writers: list[ExactlyOnceWriter]
) -> None:
    """Seqs between batches that the edge acknowledged or dropped (evicted, corrupt, skipped at a
    restart) are not waited for."""
    data, _marks = topics
    a, _b = writers
    assert write(a, batch(data, range(1, 11))).status == "ok"
    assert write(a, batch(data, range(500, 510), acked=499)).status == "ok"
    assert committed_values(kafka_bootstrap, data) == values(range(1, 11)) + values(range(500, 510))
    assert a.stats.out_of_order == 0


def test_a_batch_sent_again_shares_the_fate_of_the_batch_it_repeats(
    kafka_bootstrap: str, topics: tuple[str, str], writers: list[ExactlyOnceWriter]
) -> None:
    """The edge sent 11..20 again (its first answer was late) while the first copy waited in the
    same group: the copy is answered as the transaction writing the first one ends, never ok
    while its records are not in Kafka."""
    data, _marks = topics
    a, _b = writers
    first = batch(data, range(1, 11))
    second = batch(data, range(11, 21), acked=10)
    answers = submit_all(
        a, [(first, produce_all(first)), (second, failing(second)), (second, produce_all(second))]
    )
    assert [x.status for x in answers] == ["ok", "error", "error"]
    assert committed_values(kafka_bootstrap, data) == values(range(1, 11))
    third = batch(data, range(21, 31), acked=20)
    answers = submit_all(
        a, [(second, produce_all(second)), (third, produce_all(third)), (third, produce_all(third))]
    )
    assert [x.status for x in answers] == ["ok", "ok", "ok"]
    assert committed_values(kafka_bootstrap, data) == values(range(1, 31))


def test_an_answer_that_fails_does_not_stop_the_stream(
    topics: tuple[str, str], writers: list[ExactlyOnceWriter]
) -> None:
    """The edge's query was gone when its answer came: the batches behind it are still answered."""
    data, _marks = topics
    a, _b = writers
    answered = threading.Event()

    def gone(_ack: Ack) -> None:
        answered.set()
        raise RuntimeError("the query was dropped")

    part = batch(data, range(1, 11))
    a.submit(Pending(part, part.last_seq, at_or_below(part)), produce_all(part), gone)
    assert answered.wait(30)
    later = batch(data, range(11, 21))
    assert write(a, later).status == "ok", "the stream's writer stopped at the failed answer"
