"""A full spool: block, drop_oldest and drop_newest exactly as documented, every drop counted."""

from __future__ import annotations

import threading
from pathlib import Path

import pytest

from fleetlink.edge.errors import SpoolClosedError, SpoolFullError
from fleetlink.edge.spool import FullPolicy, Spool, SpoolOptions, SpoolStats
from tests.helpers import wait_until

RECORD = b"r" * 100  # a 128-byte frame; 4 KiB segments hold 31 of them


def options(policy: FullPolicy, timeout: float = 0.2) -> SpoolOptions:
    return SpoolOptions(
        segment_bytes=4096, max_bytes=16384, policy=policy, block_timeout_s=timeout, group_records=1
    )


def read_all(spool: Spool, *, ack: bool = True) -> list[int]:
    seqs: list[int] = []
    while (batch := spool.read_unacked(1000, 1 << 20)) is not None:
        seqs.extend(r.seq for r in batch.records)
        if ack:
            spool.ack(batch.first_seq)
    return seqs


def balanced(stats: SpoolStats) -> bool:
    """Every appended record is acked, dropped, or still held."""
    return stats.appended == stats.acked + stats.dropped_oldest + stats.depth


def test_drop_oldest_loses_exactly_what_it_counts(tmp_path: Path) -> None:
    with Spool(tmp_path, options("drop_oldest")) as spool:
        seqs = spool.append_many([RECORD] * 1000)
        assert seqs == list(range(1, 1001))  # every append is taken
        stats = spool.stats()
        assert stats.bytes <= 16384
        assert stats.dropped_oldest > 0
        assert balanced(stats)
        survivors = read_all(spool)
        assert survivors == list(range(stats.dropped_oldest + 1, 1001))  # the newest, contiguous


@pytest.mark.parametrize("outcome", ["acked", "released"])
def test_drop_oldest_with_a_batch_in_flight(tmp_path: Path, outcome: str) -> None:
    with Spool(tmp_path, options("drop_oldest")) as spool:
        spool.append_many([RECORD] * 20)
        flying = spool.read_unacked(10, 1 << 20)
        assert flying is not None
        spool.append_many([RECORD] * 500)  # evicts the segment under the batch in flight
        before = spool.stats()
        assert before.in_flight == 0  # the orphaned batch is no longer held
        if outcome == "acked":
            assert spool.ack(flying.first_seq)  # it reached Kafka after all: not lost
            after = spool.stats()
            assert after.dropped_oldest == before.dropped_oldest
            assert after.acked == 10
        else:
            assert spool.release(flying.first_seq)  # it will never be sent again: lost, counted
            after = spool.stats()
            assert after.dropped_oldest == before.dropped_oldest + 10
        assert spool.read_unacked(1000, 1 << 20) is not None
        assert balanced(spool.stats())


def test_drop_oldest_counts_records_queued_for_resending(tmp_path: Path) -> None:
    with Spool(tmp_path, options("drop_oldest")) as spool:
        spool.append_many([RECORD] * 20)
        batch = spool.read_unacked(10, 1 << 20)
        assert batch is not None
        spool.release(batch.first_seq)
        spool.append_many([RECORD] * 500)
        stats = spool.stats()
        assert balanced(stats)
        assert read_all(spool) == list(range(stats.dropped_oldest + 1, 521))


def test_drop_newest_rejects_and_counts(tmp_path: Path) -> None:
    with Spool(tmp_path, options("drop_newest")) as spool:
        results = spool.append_many([RECORD] * 200)
        taken = [s for s in results if s is not None]
        rejected = results.count(None)
        stats = spool.stats()
        assert rejected > 0
        assert stats.dropped_newest == rejected
        assert stats.appended == len(taken)
        assert results[: len(taken)] == taken  # the first ones are kept, later ones refused
        assert read_all(spool) == taken
        assert spool.append(RECORD) is not None  # room again once acked


def test_block_times_out_with_spool_full_and_counts(tmp_path: Path) -> None:
    with Spool(tmp_path, options("block", timeout=0.1)) as spool:
        with pytest.raises(SpoolFullError) as info:
            spool.append_many([RECORD] * 200)
        taken = info.value.taken
        assert 0 < taken < 200
        stats = spool.stats()
        assert (stats.block_timeouts, stats.appended, stats.dropped_newest) == (1, taken, 0)
        assert read_all(spool) == list(range(1, taken + 1))
        assert spool.append(RECORD) == taken + 1


def test_block_waits_for_acks_then_takes_the_record(tmp_path: Path) -> None:
    with Spool(tmp_path, options("block", timeout=20)) as spool:
        taken = 0
        while spool.stats().bytes + 2 * 128 < 16384 - 4096:
            spool.append(RECORD)
            taken += 1
        result: list[int | None] = []
        thread = threading.Thread(target=lambda: result.extend(spool.append_many([RECORD] * 100)))
        thread.start()
        wait_until(lambda: spool.stats().blocked_appenders == 1, timeout=10, message="appender blocked")
        assert not result
        assert len(read_all(spool)) >= taken  # acks free whole segments
        thread.join(timeout=10)
        assert result == list(range(taken + 1, taken + 101))
        assert spool.stats().block_timeouts == 0


def test_close_wakes_a_blocked_appender(tmp_path: Path) -> None:
    spool = Spool(tmp_path, options("block", timeout=30)).open()
    errors: list[BaseException] = []

    def append() -> None:
        try:
            spool.append_many([RECORD] * 1000)
        except SpoolClosedError as exc:
            errors.append(exc)

    thread = threading.Thread(target=append)
    thread.start()
    wait_until(lambda: spool.stats().blocked_appenders == 1, timeout=10, message="appender blocked")
    spool.close()
    thread.join(timeout=10)
    assert not thread.is_alive()
    assert len(errors) == 1
