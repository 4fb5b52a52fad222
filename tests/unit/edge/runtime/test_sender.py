"""The WAN sender against a scripted uplink (no sockets): acks, retries, window, linger, stop."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import pytest

from fleetlink.edge.runtime.encoding import identity_of
from fleetlink.edge.runtime.schema_book import SchemaBook
from fleetlink.edge.runtime.sender import SenderOptions, WanSender, answer_wakes
from fleetlink.edge.runtime.transport import Done
from fleetlink.edge.spool import MemoryBuffer
from fleetlink.wire import (
    Ack,
    Batch,
    Record,
    RecordFailure,
    decode_batch,
    encode_ack,
    encode_payload,
    single_object,
)
from tests.helpers import wait_until

SCHEMA_A = identity_of({"type": "record", "name": "A", "fields": [{"name": "x", "type": "long"}]})
SCHEMA_B = identity_of({"type": "record", "name": "B", "fields": [{"name": "y", "type": "long"}]})
FAST = SenderOptions(
    batch_max_records=10,
    batch_max_bytes=1 << 20,
    linger_s=0.0,
    ack_timeout_s=1.0,
    max_in_flight=4,
    backoff_min_s=0.001,
    backoff_max_s=0.005,
    codec="zlib",
)

Answer = tuple[bytes | None, str | None] | None
Policy = Callable[[Batch, int], Answer]


def ok(batch: Batch, failures: tuple[RecordFailure, ...] = ()) -> Answer:
    return encode_ack(Ack(batch.edge_id, batch.stream, batch.first_seq, batch.last_seq, "ok", failures)), None


class ScriptedUplink:
    """A transport whose answers come from ``policy(batch, attempt)``; ``None`` holds the batch."""

    def __init__(self, policy: Policy) -> None:
        self.policy = policy
        self.batches: list[Batch] = []
        self.held: list[tuple[Batch, Done]] = []
        self.lock = threading.Lock()

    def send(self, payload: bytes, timeout_s: float, done: Done) -> None:
        batch = decode_batch(payload)
        with self.lock:
            attempt = sum(1 for b in self.batches if b.first_seq == batch.first_seq)
            self.batches.append(batch)
            answer = self.policy(batch, attempt)
            if answer is None:
                self.held.append((batch, done))
                return
        done(*answer)

    def release_held(self, answer: Callable[[Batch], Answer]) -> None:
        with self.lock:
            held, self.held = self.held, []
        for batch, done in held:
            result = answer(batch)
            if result is not None:
                done(*result)

    def delivered_seqs(self) -> list[int]:
        return [r.seq for b in self.batches for r in b.records]


def payload(i: int, schema: bytes = SCHEMA_A.fingerprint) -> bytes:
    return encode_payload(Record(kafka_topic="t", key=b"k", value=single_object(schema, bytes([i % 256]))))


@contextmanager
def running(
    uplink: ScriptedUplink,
    buffer: MemoryBuffer,
    options: SenderOptions = FAST,
    book: SchemaBook | None = None,
) -> Iterator[WanSender]:
    if book is None:
        book = SchemaBook()
        book.add(SCHEMA_A.fingerprint, SCHEMA_A.json)
        book.add(SCHEMA_B.fingerprint, SCHEMA_B.json)
    sender = WanSender(buffer, uplink, book, site="s1", edge_id="e1", options=options)
    sender.start()
    try:
        yield sender
    finally:
        sender.stop(timeout_s=1.0)


def drained(buffer: MemoryBuffer) -> Callable[[], bool]:
    return lambda: buffer.stats().depth == 0


def test_everything_is_delivered_in_batches_with_their_schemas() -> None:
    buffer = MemoryBuffer(first_seq=1, group_records=FAST.batch_max_records)
    buffer.append_many([payload(i) for i in range(25)] + [payload(99, SCHEMA_B.fingerprint)])
    uplink = ScriptedUplink(lambda batch, attempt: ok(batch))
    with running(uplink, buffer) as sender:
        sender.wake()
        wait_until(drained(buffer), 5, message="buffer drained")
    assert [len(b.records) for b in uplink.batches] == [10, 10, 6]
    assert uplink.delivered_seqs() == list(range(1, 27))
    # This uplink answers at once: each answer is applied before the next batch, so a schema's text
    # travels until the first batch that carried it is acknowledged, then only its fingerprint.
    assert [set(b.schemas) for b in uplink.batches] == [
        {SCHEMA_A.fingerprint},
        set(),
        {SCHEMA_B.fingerprint},
    ]
    assert uplink.batches[0].schemas[SCHEMA_A.fingerprint] == SCHEMA_A.json
    assert {(b.site, b.edge_id, b.stream) for b in uplink.batches} == {("s1", "e1", "memory")}
    stats = sender.stats
    assert (stats.batches_sent, stats.batches_acked) == (3, 3)
    assert (stats.records_acked, stats.batches_retried) == (26, 0)
    assert stats.schemas_elided == 2
    assert buffer.stats().acked == 26


@pytest.mark.parametrize(
    "failure",
    [
        (None, "no uplink answered on fleetlink/s1/ingest/e1"),
        (b"not an ack", None),
        ("error-ack", None),
        ("wrong-range", None),
    ],
)
def test_failed_batches_are_resent_until_acknowledged(
    failure: tuple[bytes | str | None, str | None], caplog: pytest.LogCaptureFixture
) -> None:
    def policy(batch: Batch, attempt: int) -> Answer:
        if attempt >= 3:
            return ok(batch)
        reply, error = failure
        if reply == "error-ack":
            return encode_ack(
                Ack("e1", batch.stream, batch.first_seq, batch.last_seq, "error", detail="Kafka is down")
            ), None
        if reply == "wrong-range":
            return encode_ack(Ack("e1", batch.stream, batch.first_seq, batch.last_seq + 1, "ok")), None
        return (reply if isinstance(reply, bytes) else None), error

    buffer = MemoryBuffer(first_seq=1, group_records=FAST.batch_max_records)
    buffer.append_many([payload(i) for i in range(5)])
    uplink = ScriptedUplink(policy)
    caplog.set_level(logging.WARNING, logger="fleetlink.edge.runtime.sender")
    with running(uplink, buffer) as sender:
        sender.wake()
        wait_until(drained(buffer), 5, message="buffer drained")
    assert [b.first_seq for b in uplink.batches] == [1, 1, 1, 1]
    assert uplink.delivered_seqs() == [1, 2, 3, 4, 5] * 4
    assert sender.stats.batches_retried == 3
    assert sender.stats.outages == 1
    warnings = [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(warnings) == 2  # the outage started, the outage ended: not one per retry
    assert "not acknowledged" in warnings[0].getMessage()
    assert "acknowledges again" in warnings[1].getMessage()


def test_dead_lettered_records_are_counted_and_acked() -> None:
    def policy(batch: Batch, attempt: int) -> Answer:
        failures = (RecordFailure(batch.first_seq, "MSG_SIZE_TOO_LARGE", dead_lettered=True),)
        return ok(batch, failures)

    buffer = MemoryBuffer(first_seq=1, group_records=FAST.batch_max_records)
    buffer.append_many([payload(i) for i in range(3)])
    uplink = ScriptedUplink(policy)
    with running(uplink, buffer) as sender:
        sender.wake()
        wait_until(drained(buffer), 5)
    assert sender.stats.records_dead_lettered == 1
    assert sender.stats.records_acked == 3


def test_window_of_batches_in_flight() -> None:
    buffer = MemoryBuffer(first_seq=1, group_records=FAST.batch_max_records)
    buffer.append_many([payload(i) for i in range(100)])
    uplink = ScriptedUplink(lambda batch, attempt: None)  # hold every batch
    with running(uplink, buffer) as sender:
        sender.wake()
        wait_until(lambda: len(uplink.held) == 4, 5, message="4 batches in flight")
        assert buffer.stats().in_flight == 40
        assert sender.stats.in_flight == 4
        uplink.policy = lambda batch, attempt: ok(batch)
        uplink.release_held(ok)
        wait_until(drained(buffer), 5)
    assert sorted(b.first_seq for b in uplink.batches) == list(range(1, 101, 10))


def test_after_a_failure_one_batch_probes_before_the_window_opens() -> None:
    buffer = MemoryBuffer(first_seq=1, group_records=FAST.batch_max_records)
    buffer.append_many([payload(i) for i in range(60)])
    uplink = ScriptedUplink(lambda batch, attempt: None)
    with running(uplink, buffer):
        wait_until(lambda: len(uplink.held) == 4, 5)
        uplink.release_held(lambda batch: (None, "timeout"))  # the whole window fails
        wait_until(lambda: len(uplink.held) == 1, 5, message="one probe")
        probe = uplink.held[0][0]
        assert probe.first_seq == 1  # released batches are sent again first, in order
        assert len(uplink.batches) == 5
        uplink.policy = lambda batch, attempt: ok(batch)
        uplink.release_held(ok)
        wait_until(drained(buffer), 5)
    firsts = [b.first_seq for b in uplink.batches]
    assert firsts[:5] == [1, 11, 21, 31, 1]
    assert sorted(set(firsts)) == [1, 11, 21, 31, 41, 51]


def test_linger_fills_a_batch_after_the_previous_one_and_a_quiet_stream_sends_at_once() -> None:
    buffer = MemoryBuffer(first_seq=1, group_records=FAST.batch_max_records)
    uplink = ScriptedUplink(lambda batch, attempt: ok(batch))
    options = SenderOptions(batch_max_records=10, linger_s=30.0, backoff_min_s=0.001, backoff_max_s=0.01)
    sender = WanSender(buffer, uplink, SchemaBook(), site="s1", edge_id="e1", options=options).start()
    buffer.append(payload(0))
    sender.wake()
    wait_until(drained(buffer), 5)  # a quiet stream: the first record does not wait the 30 s
    for i in range(1, 6):
        buffer.append(payload(i))
        sender.wake()  # each wake-up finds a partial batch within the linger of the last one
    sender.stop(timeout_s=5.0)  # stopping sends what the linger holds
    assert [len(b.records) for b in uplink.batches] == [1, 5]


def test_pump_sends_full_batches_from_the_calling_thread_and_leaves_the_rest() -> None:
    buffer = MemoryBuffer(first_seq=1, group_records=FAST.batch_max_records)
    buffer.append_many([payload(i) for i in range(25)])
    threads: list[str] = []

    def policy(batch: Batch, attempt: int) -> Answer:
        threads.append(threading.current_thread().name)
        return ok(batch)

    uplink = ScriptedUplink(policy)
    options = SenderOptions(
        batch_max_records=10, linger_s=30.0, max_in_flight=4, backoff_min_s=0.001, backoff_max_s=0.01
    )
    sender = WanSender(buffer, uplink, SchemaBook(), site="s1", edge_id="e1", options=options)
    sender.pump()  # the sender's own thread is not even running: the caller sends
    assert [len(b.records) for b in uplink.batches] == [10, 10]
    assert threads == [threading.current_thread().name] * 2
    sender.start()  # answers the two batches; the partial one waits for the linger
    wait_until(lambda: buffer.stats().acked == 20, 5)
    sender.stop(timeout_s=5.0)
    assert [len(b.records) for b in uplink.batches] == [10, 10, 5]
    assert buffer.stats().depth == 0


def test_stop_is_bounded_and_leaves_unacked_records_in_the_buffer() -> None:
    buffer = MemoryBuffer(first_seq=1, group_records=FAST.batch_max_records)
    buffer.append_many([payload(i) for i in range(30)])
    uplink = ScriptedUplink(lambda batch, attempt: None)  # the uplink never answers
    sender = WanSender(buffer, uplink, SchemaBook(), site="s1", edge_id="e1", options=FAST).start()
    wait_until(lambda: len(uplink.held) == 3, 5)
    sender.stop(timeout_s=0.2)
    stats = buffer.stats()
    assert (stats.depth, stats.in_flight, stats.acked) == (30, 0, 0)
    again = buffer.read_unacked(100, 1 << 20)
    assert again is not None
    assert again.first_seq == 1
    assert sender.stats.missing_schemas > 0


def test_stop_drains_what_can_be_sent() -> None:
    buffer = MemoryBuffer(first_seq=1, group_records=FAST.batch_max_records)
    uplink = ScriptedUplink(lambda batch, attempt: ok(batch))
    sender = WanSender(
        buffer,
        uplink,
        SchemaBook(),
        site="s1",
        edge_id="e1",
        options=SenderOptions(linger_s=10.0, batch_max_records=100),
    ).start()
    buffer.append(payload(0))
    sender.wake()
    wait_until(drained(buffer), 5)
    buffer.append_many([payload(i) for i in range(1, 31)])
    sender.wake()
    sender.stop(timeout_s=5.0)  # the linger would hold the partial batch for 10 s; stopping sends it now
    assert buffer.stats().depth == 0
    assert [len(b.records) for b in uplink.batches] == [1, 30]


def need_schemas(batch: Batch, missing: frozenset[bytes]) -> Answer:
    return encode_ack(
        Ack(
            batch.edge_id,
            batch.stream,
            batch.first_seq,
            batch.last_seq,
            "need_schemas",
            missing_schemas=tuple(sorted(missing)),
        )
    ), None


def send_and_drain(sender: WanSender, buffer: MemoryBuffer, payloads: list[bytes]) -> None:
    buffer.append_many(payloads)
    sender.wake()
    wait_until(drained(buffer), 5, message="buffer drained")


def test_a_schema_travels_until_a_batch_carrying_it_is_acknowledged_then_its_fingerprint_alone() -> None:
    buffer = MemoryBuffer(first_seq=1, group_records=FAST.batch_max_records)
    uplink = ScriptedUplink(lambda batch, attempt: ok(batch))
    with running(uplink, buffer) as sender:
        send_and_drain(sender, buffer, [payload(i) for i in range(3)])
        send_and_drain(sender, buffer, [payload(i) for i in range(3)] + [payload(9, SCHEMA_B.fingerprint)])
        send_and_drain(sender, buffer, [payload(9, SCHEMA_B.fingerprint)])
    assert [(set(b.schemas), set(b.elided)) for b in uplink.batches] == [
        ({SCHEMA_A.fingerprint}, set()),
        ({SCHEMA_B.fingerprint}, {SCHEMA_A.fingerprint}),
        (set(), {SCHEMA_B.fingerprint}),
    ]
    assert sender.stats.schemas_elided == 2


def test_an_uplink_without_a_left_out_schema_gets_the_batch_again_at_once_with_it() -> None:
    buffer = MemoryBuffer(first_seq=1, group_records=FAST.batch_max_records)
    learned: set[bytes] = set()  # the texts the uplink has read

    def policy(batch: Batch, attempt: int) -> Answer:
        learned.update(batch.schemas)
        if batch.elided - learned:
            return need_schemas(batch, batch.elided - learned)
        return ok(batch)

    uplink = ScriptedUplink(policy)
    slow_retry = SenderOptions(
        batch_max_records=10,
        linger_s=0.0,
        max_in_flight=4,
        backoff_min_s=30.0,
        backoff_max_s=30.0,
        codec="zlib",
    )
    with running(uplink, buffer, slow_retry) as sender:
        send_and_drain(sender, buffer, [payload(1)])
        learned.clear()  # the uplink restarted
        send_and_drain(sender, buffer, [payload(2)])  # well within the 30 s backoff: none was used
        send_and_drain(sender, buffer, [payload(3)])
    assert [(b.first_seq, set(b.schemas), set(b.elided)) for b in uplink.batches] == [
        (1, {SCHEMA_A.fingerprint}, set()),
        (2, set(), {SCHEMA_A.fingerprint}),  # refused: nothing produced
        (2, {SCHEMA_A.fingerprint}, set()),  # the same records, with the text
        (3, set(), {SCHEMA_A.fingerprint}),
    ]
    assert uplink.delivered_seqs() == [1, 2, 2, 3]
    stats = sender.stats
    assert (stats.schema_requests, stats.batches_retried, stats.outages, stats.records_acked) == (1, 0, 0, 3)


def test_a_request_for_a_schema_the_batch_carried_is_a_failure_retried_with_backoff() -> None:
    buffer = MemoryBuffer(first_seq=1, group_records=FAST.batch_max_records)

    def policy(batch: Batch, attempt: int) -> Answer:
        if attempt == 0:
            return encode_ack(
                Ack(
                    batch.edge_id,
                    batch.stream,
                    batch.first_seq,
                    batch.last_seq,
                    "need_schemas",
                    missing_schemas=(SCHEMA_A.fingerprint,),
                )
            ), None
        return ok(batch)

    uplink = ScriptedUplink(policy)
    with running(uplink, buffer) as sender:
        send_and_drain(sender, buffer, [payload(1)])
    assert [set(b.schemas) for b in uplink.batches] == [{SCHEMA_A.fingerprint}] * 2
    assert "did not leave out" in sender.last_error
    assert (sender.stats.batches_retried, sender.stats.schema_requests) == (1, 0)


def test_records_may_bring_their_own_linger_and_the_shortest_waiting_one_counts() -> None:
    buffer = MemoryBuffer(first_seq=1, group_records=FAST.batch_max_records)
    uplink = ScriptedUplink(lambda batch, attempt: ok(batch))
    options = SenderOptions(batch_max_records=10, linger_s=0.0, backoff_min_s=0.001, backoff_max_s=0.01)
    sender = WanSender(buffer, uplink, SchemaBook(), site="s1", edge_id="e1", options=options).start()
    try:
        buffer.append(payload(0))
        sender.pump()
        wait_until(drained(buffer), 5)
        for i in range(1, 4):  # e.g. window records of an aggregate mapping: they may wait 30 s
            buffer.append(payload(i))
            sender.pump(30.0)
        wait_until(lambda: sender.snapshot()["in_flight"] == 0, 5)
        assert len(uplink.batches) == 1
        buffer.append(payload(4))
        sender.pump(None)  # a record with the stream's linger (0 s): everything waiting leaves now
        wait_until(drained(buffer), 5)
    finally:
        sender.stop(timeout_s=5.0)
    assert [len(b.records) for b in uplink.batches] == [1, 4]


@pytest.mark.parametrize(
    ("case", "asleep_until", "failed", "window_full", "stopping", "wakes"),
    [
        ("asleep until the next batch, within the linger", 10.015, False, False, False, False),
        ("asleep for longer than the linger (nothing was due)", 10.050, False, False, False, True),
        ("awake, or about to choose its sleep", None, False, False, False, True),
        ("a failure: the retry starts now", 10.015, True, False, False, True),
        ("the window is full: the answer frees a place", 10.015, False, True, False, True),
        ("stopping: waits for the answers in flight", 10.015, False, False, True, True),
    ],
)
def test_an_answer_waits_for_the_planned_wake_up_only_when_nothing_needs_it(
    case: str, asleep_until: float | None, failed: bool, window_full: bool, stopping: bool, wakes: bool
) -> None:
    got = answer_wakes(
        failed=failed,
        asleep_until=asleep_until,
        arrived=10.0,
        linger_s=0.02,
        window_full=window_full,
        stopping=stopping,
    )
    assert got is wakes, case


def batches_sent(uplink: ScriptedUplink, n: int) -> Callable[[], bool]:
    return lambda: len(uplink.batches) >= n


def test_answers_that_wait_are_applied_at_the_next_batch() -> None:
    """With a linger the sender sleeps until the next batch may leave; the answers that came
    meanwhile are applied then (or by ``pump``): nothing stays in flight."""
    options = SenderOptions(
        batch_max_records=5, linger_s=0.05, ack_timeout_s=1.0, max_in_flight=4, codec="zlib"
    )
    buffer = MemoryBuffer(first_seq=1, group_records=5)
    uplink = ScriptedUplink(lambda batch, attempt: None)  # answers held, released below
    with running(uplink, buffer, options) as sender:
        for i in range(3):
            buffer.append_many([payload(10 * i + k) for k in range(3)])
            sender.pump()
            wait_until(batches_sent(uplink, i + 1), 5, message="batch sent")
            uplink.release_held(ok)
        wait_until(drained(buffer), 5, message="every answer applied")
        assert (sender.stats.batches_acked, sender.stats.in_flight) == (3, 0)
        assert sender.ack_latency.totals().count == 3


def test_batches_held_back_behind_a_failed_one_go_again_after_it_without_a_backoff_step_each() -> None:
    """The uplink fails the first batch and holds back the one sent behind it (``held_back``): the
    edge sends one batch at a time until the first is through, the records arrive in order, and
    the outage counts one retry (one backoff step), not one per batch."""
    buffer = MemoryBuffer(first_seq=1, group_records=FAST.batch_max_records)
    buffer.append_many([payload(i) for i in range(40)])

    def policy(batch: Batch, attempt: int) -> Answer:
        if batch.first_seq == 1 and attempt == 0:
            return None  # answered below, once the batches behind it were held back
        if batch.first_seq > 1 and 1 not in delivered:
            return encode_ack(
                Ack(batch.edge_id, batch.stream, batch.first_seq, batch.last_seq, "held_back", detail="1..")
            ), None
        delivered.append(batch.first_seq)
        return ok(batch)

    delivered: list[int] = []
    uplink = ScriptedUplink(policy)
    with running(uplink, buffer) as sender:
        sender.wake()
        wait_until(lambda: sender.stats.batches_held_back == 1, 5, message="the second batch held back")
        assert [b.first_seq for b in uplink.batches] == [1, 11]  # then one at a time: the first in flight
        uplink.release_held(
            lambda b: (
                encode_ack(Ack(b.edge_id, b.stream, b.first_seq, b.last_seq, "error", detail="registry")),
                None,
            )
        )
        wait_until(drained(buffer), 5, message="buffer drained")
    assert delivered == [1, 11, 21, 31]
    assert [b.first_seq for b in uplink.batches] == [1, 11, 1, 11, 21, 31]
    stats = sender.stats
    assert (stats.batches_held_back, stats.batches_retried, stats.outages) == (1, 1, 1)
