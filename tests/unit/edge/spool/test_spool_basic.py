"""The durable spool: append, read, ack, re-send, reopen, fsync policies (real files in tmp_path)."""

from __future__ import annotations

import os
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

from fleetlink.edge.errors import SpoolClosedError, SpoolError, SpoolLockedError
from fleetlink.edge.spool import FsyncPolicy, Spool, SpoolOptions
from fleetlink.edge.spool.ledger import RESERVE, encode_entry
from fleetlink.edge.spool.spool import RESERVE_BLOCK
from tests.helpers import wait_until

SMALL = SpoolOptions(segment_bytes=8192, max_bytes=1 << 20, group_records=1)  # a frame per record


def crash(spool: Spool) -> None:
    """What a crash leaves: the files as written, no clean-close entry, the lock released."""
    spool._stop.set()
    if spool._flusher is not None:
        spool._flusher.join()
    spool._writer.seal()
    spool._ledger.close()
    os.close(spool._lock_fd)


class Clock:
    def __init__(self) -> None:
        self.now = 1_000_000

    def __call__(self) -> int:
        return self.now


def payload(i: int) -> bytes:
    return f"record-{i:06d}".encode() * 3


def drain(spool: Spool, *, ack: bool = True, max_records: int = 50) -> list[int]:
    seqs: list[int] = []
    while (batch := spool.read_unacked(max_records, 1 << 20)) is not None:
        seqs.extend(r.seq for r in batch.records)
        if ack:
            spool.ack(batch.first_seq)
    return seqs


@pytest.fixture
def spool(tmp_path: Path) -> Iterator[Spool]:
    with Spool(tmp_path / "spool", SMALL) as opened:
        yield opened


def test_append_returns_increasing_seqs_and_records_come_back_in_order(spool: Spool) -> None:
    seqs = [spool.append(payload(i)) for i in range(300)]
    assert seqs == list(range(1, 301))
    batch = spool.read_unacked(100, 1 << 20)
    assert batch is not None
    assert (batch.stream, batch.first_seq, batch.last_seq) == ("durable", 1, 100)
    assert [r.payload for r in batch.records] == [payload(i) for i in range(100)]
    assert batch.nbytes == sum(len(payload(i)) + 10 for i in range(100))  # + a group header and length each


def test_batches_respect_max_records_and_max_bytes_and_segment_ends(spool: Spool) -> None:
    for _ in range(10):  # 7 frames of 1028 bytes fill an 8 KiB segment
        spool.append(b"a" * 1000)
    sizes = []
    while (batch := spool.read_unacked(4, 2500)) is not None:
        sizes.append(len(batch.records))
    assert sizes == [2, 2, 2, 1, 2, 1]  # a batch never spans two segments
    spool.append_many([b"c" * 10] * 10)
    batch = spool.read_unacked(4, 1 << 20)
    assert batch is not None
    assert len(batch.records) == 4
    rest = spool.read_unacked(100, 1 << 20)
    assert rest is not None
    assert len(rest.records) == 6
    spool.append(b"b" * 5000)
    big = spool.read_unacked(10, 100)
    assert big is not None
    assert len(big.records) == 1  # one record bigger than max_bytes still goes, alone


def test_ack_advances_and_deletes_acked_segments(spool: Spool) -> None:
    for i in range(0, 1000, 50):
        spool.append_many([payload(n) for n in range(i, i + 50)])
    before = spool.stats()
    assert before.segments > 3
    assert drain(spool) == list(range(1, 1001))
    after = spool.stats()
    assert (after.depth, after.acked, after.in_flight) == (0, 1000, 0)
    assert after.segments <= 1  # the active segment stays until it is full
    assert after.bytes < before.bytes


def test_out_of_order_acks_and_release_resend_exactly_the_same_batch(spool: Spool) -> None:
    spool.append_many([payload(i) for i in range(30)])
    a, b, c = (spool.read_unacked(10, 1 << 20) for _ in range(3))
    assert a is not None
    assert b is not None
    assert c is not None
    assert spool.stats().in_flight == 30
    assert spool.ack(c.first_seq)
    assert spool.release(b.first_seq)
    again = spool.read_unacked(10, 1 << 20)
    assert again == b
    assert spool.ack(again.first_seq)
    assert not spool.ack(again.first_seq)  # stale: counted, harmless
    assert spool.read_unacked(10, 1 << 20) is None
    assert spool.stats().depth == 10  # a is still in flight
    assert spool.stats().stale_acks == 1
    spool.release_all()
    assert spool.read_unacked(10, 1 << 20) == a


def test_a_batch_carries_the_ack_mark_it_was_handed_out_under(spool: Spool) -> None:
    """``acked``: every record at or below it is done; what lies between it and the batch may still
    be sent (an exactly-once uplink must not write past it: docs/exactly-once.md)."""
    spool.append_many([payload(i) for i in range(30)])
    a, b = spool.read_unacked(10, 1 << 20), spool.read_unacked(10, 1 << 20)
    assert a is not None
    assert b is not None
    assert (a.acked, b.acked) == (0, 0)  # a still in flight when b left
    assert spool.release(a.first_seq)
    again = spool.read_unacked(10, 1 << 20)
    assert again is not None
    assert again.acked == 0
    assert spool.ack(a.first_seq)
    assert spool.ack(b.first_seq)
    c = spool.read_unacked(10, 1 << 20)
    assert c is not None
    assert c.acked == c.first_seq - 1 == 20  # everything before it acknowledged


def test_a_late_ack_for_a_released_batch_is_accepted(spool: Spool) -> None:
    spool.append_many([payload(i) for i in range(5)])
    batch = spool.read_unacked(10, 1 << 20)
    assert batch is not None
    spool.release(batch.first_seq)
    assert spool.ack(batch.first_seq)
    assert spool.read_unacked(10, 1 << 20) is None
    assert spool.stats().depth == 0


def test_skip_in_flight_false_restarts_from_first_unacked(spool: Spool) -> None:
    spool.append_many([payload(i) for i in range(20)])
    first = spool.read_unacked(10, 1 << 20)
    assert first is not None
    spool.read_unacked(10, 1 << 20)
    again = spool.read_unacked(10, 1 << 20, skip_in_flight=False)
    assert again == first


def test_reopen_resumes_from_first_unacked_and_keeps_seqs_increasing(tmp_path: Path) -> None:
    with Spool(tmp_path, SMALL) as spool:
        spool.append_many([payload(i) for i in range(500)])
        for _ in range(3):
            batch = spool.read_unacked(100, 1 << 20)
            assert batch is not None
            if batch.first_seq != 101:
                spool.ack(batch.first_seq)  # 1..100 and 201..300 acked, 101..200 in flight
    with Spool(tmp_path, SMALL) as spool:
        # only the contiguous mark (100) is persisted: 201..300, acked behind the batch still in
        # flight, is sent again (duplicates within the in-flight window, never a loss)
        assert spool.stats().depth == 400
        assert drain(spool, ack=False) == list(range(101, 501))
        assert spool.append(b"new") == 501  # clean stop: seqs continue


def test_unclean_stop_skips_to_the_reserved_bound(tmp_path: Path) -> None:
    spool = Spool(tmp_path, SMALL).open()
    spool.append_many([payload(i) for i in range(10)])
    crash(spool)
    with Spool(tmp_path, SMALL) as again:
        assert drain(again, ack=False) == list(range(1, 11))
        # the first append reserved seqs below 2 + RESERVE_BLOCK; any of them may have left
        assert again.append(b"x") == 2 + RESERVE_BLOCK


def test_reservation_is_durable_before_seqs_are_used(tmp_path: Path) -> None:
    with Spool(tmp_path, SMALL) as spool:
        spool.append(b"x")
    ledger = (tmp_path / "ledger").read_bytes()
    assert encode_entry(RESERVE, 2 + RESERVE_BLOCK) in ledger


def test_oldest_age_uses_append_time(tmp_path: Path) -> None:
    clock = Clock()
    with Spool(tmp_path, SMALL, clock=clock) as spool:
        assert spool.stats().oldest_append_ms is None
        spool.append(b"a")
        clock.now += 500
        spool.append(b"b")
        clock.now += 500
        stats = spool.stats()
        assert stats.oldest_append_ms == 1_000_000
        assert stats.oldest_age_ms(clock.now) == 1000
        batch = spool.read_unacked(1, 1 << 20)
        assert batch is not None
        assert batch.records[0].timestamp_ms == 1_000_000
        assert spool.stats().oldest_append_ms == 1_000_000  # in flight still counts
        spool.ack(batch.first_seq)
        assert spool.stats().oldest_append_ms == 1_000_500
        assert spool.stats().oldest_age_ms(clock.now) == 500


@pytest.mark.parametrize(("policy", "calls", "expected"), [("always", 5, 5), ("batch", 10, 2)])
def test_fsync_policies_sync_in_the_append_path(
    tmp_path: Path, policy: FsyncPolicy, calls: int, expected: int
) -> None:
    options = SpoolOptions(
        segment_bytes=1 << 20, max_bytes=4 << 20, fsync=policy, fsync_batch=50, fsync_interval_ms=60_000
    )
    with Spool(tmp_path, options) as spool:
        for _ in range(calls):
            spool.append_many([b"r"] * 10)
        assert spool.stats().fsyncs == expected


def test_interval_policy_syncs_in_the_background(tmp_path: Path) -> None:
    # an hour apart: the append itself does not sync (whatever the machine's pace)
    hourly = SpoolOptions(
        segment_bytes=1 << 20, max_bytes=4 << 20, fsync="interval", fsync_interval_ms=3_600_000
    )
    with Spool(tmp_path / "hourly", hourly) as spool:
        spool.append(b"r")
        assert spool.stats().fsyncs == 0
    options = SpoolOptions(segment_bytes=1 << 20, max_bytes=4 << 20, fsync="interval", fsync_interval_ms=20)
    with Spool(tmp_path / "often", options) as spool:
        spool.append(b"r")
        wait_until(lambda: spool.stats().fsyncs >= 1, timeout=5, message="background fsync")


def test_a_second_spool_on_the_same_directory_is_refused(spool: Spool) -> None:
    with pytest.raises(SpoolLockedError, match="open elsewhere"):
        Spool(spool.directory, SMALL).open()


def test_use_after_close_and_misuse(tmp_path: Path) -> None:
    spool = Spool(tmp_path, SMALL).open()
    spool.close()
    spool.close()
    with pytest.raises(SpoolClosedError):
        spool.append(b"x")
    with pytest.raises(SpoolError, match="opened once"):
        spool.open()
    with Spool(tmp_path, SMALL) as again:
        with pytest.raises(SpoolError, match="record limit"):
            again.append(b"x" * 9000)
        with pytest.raises(SpoolError, match="positive"):
            again.read_unacked(0, 10)


@pytest.mark.parametrize(
    ("kwargs", "reason"),
    [
        ({"policy": "sometimes"}, "policy"),
        ({"fsync": "never"}, "fsync"),
        ({"segment_bytes": 100}, "4096"),
        ({"segment_bytes": 8192, "max_bytes": 10000}, "twice"),
        ({"fsync_interval_ms": 0}, "positive"),
    ],
)
def test_bad_options(kwargs: dict[str, object], reason: str) -> None:
    with pytest.raises(SpoolError, match=reason):
        SpoolOptions(**kwargs)  # type: ignore[arg-type]


def test_one_writer_and_one_sender_thread_lose_nothing(tmp_path: Path) -> None:
    total = 20_000
    received: list[int] = []
    with Spool(tmp_path, SpoolOptions(segment_bytes=64 << 10, max_bytes=64 << 20)) as spool:

        def writer() -> None:
            for start in range(0, total, 100):
                spool.append_many([payload(i) for i in range(start, start + 100)])

        thread = threading.Thread(target=writer)
        thread.start()

        def pump() -> bool:
            batch = spool.read_unacked(300, 1 << 20)
            if batch is not None:
                received.extend(r.seq for r in batch.records)
                spool.ack(batch.first_seq)
            return len(received) == total

        wait_until(pump, timeout=20, interval=0, message="every record read and acked")
        thread.join()
        assert received == list(range(1, total + 1))
        stats = spool.stats()
        assert (stats.appended, stats.acked, stats.depth) == (total, total, 0)
