"""The memory buffer (best_effort mappings): same interface as the spool, bounded, drop_oldest."""

from __future__ import annotations

import pytest

from fleetlink.edge.errors import SpoolClosedError, SpoolError
from fleetlink.edge.spool import MemoryBuffer, RecordBuffer, SpoolStats


def balanced(stats: SpoolStats) -> bool:
    return stats.appended == stats.acked + stats.dropped_oldest + stats.depth


def test_same_loop_as_the_spool() -> None:
    buffer: RecordBuffer = MemoryBuffer(first_seq=1, group_records=1, clock=lambda: 77)
    assert buffer.append_many([b"a", b"b", b"c"]) == [1, 2, 3]
    batch = buffer.read_unacked(2, 1 << 20)
    assert batch is not None
    assert (batch.stream, batch.first_seq, batch.last_seq) == ("memory", 1, 2)
    assert [r.payload for r in batch.records] == [b"a", b"b"]
    assert batch.records[0].timestamp_ms == 77
    assert buffer.stats().in_flight == 2
    assert buffer.release(1)
    assert buffer.read_unacked(10, 1 << 20) == batch  # released batches come back first, unchanged
    assert buffer.ack(1)
    assert not buffer.ack(1)
    rest = buffer.read_unacked(10, 1 << 20)
    assert rest is not None
    assert [r.seq for r in rest.records] == [3]
    assert buffer.release_all() == 1
    assert buffer.read_unacked(10, 1 << 20, skip_in_flight=False) == rest
    stats = buffer.stats()
    assert (stats.acked, stats.depth, stats.stale_acks, stats.oldest_append_ms) == (2, 1, 1, 77)


def test_drop_oldest_by_records_and_bytes() -> None:
    buffer = MemoryBuffer(first_seq=1, group_records=1, max_records=10, max_bytes=1 << 20)
    buffer.append_many([b"x"] * 25)
    stats = buffer.stats()
    assert (stats.dropped_oldest, stats.depth) == (15, 10)
    batch = buffer.read_unacked(100, 1 << 20)
    assert batch is not None
    assert [r.seq for r in batch.records] == list(range(16, 26))
    small = MemoryBuffer(first_seq=1, group_records=1, max_bytes=100)
    small.append_many([b"y" * 30] * 5)  # 40 bytes each as a group of one
    assert small.stats().bytes == 80
    assert small.stats().dropped_oldest == 3
    assert balanced(small.stats())


def test_released_batches_go_first_and_in_flight_ones_never() -> None:
    buffer = MemoryBuffer(first_seq=1, group_records=1, max_records=6)
    buffer.append_many([b"x"] * 6)
    flying = buffer.read_unacked(3, 1 << 20)
    queued = buffer.read_unacked(2, 1 << 20)
    assert flying is not None
    assert queued is not None
    buffer.release(queued.first_seq)
    assert buffer.append(b"new") == 7  # evicts the released batch (2 records), whole
    assert buffer.stats().dropped_oldest == 2
    buffer.append_many([b"n"] * 2)  # evicts seq 6, then fits
    assert buffer.stats().dropped_oldest == 3
    assert buffer.append_many([b"m"] * 3) == [10, 11, 12]  # evicts 7, 8, 9
    assert buffer.stats().depth == 6
    buffer2 = MemoryBuffer(first_seq=1, group_records=1, max_records=2)
    buffer2.append_many([b"a", b"b"])
    assert buffer2.read_unacked(5, 1 << 20) is not None
    assert buffer2.append(b"c") is None  # everything held is in flight: the newest is dropped
    assert buffer2.stats().dropped_newest == 1
    assert balanced(buffer.stats())


def test_seqs_start_from_the_clock_so_restarts_do_not_reuse_them() -> None:
    first = MemoryBuffer().append(b"x")
    second = MemoryBuffer().append(b"x")
    assert first is not None
    assert second is not None
    assert second > first > 1_600_000_000 * 1_000_000


def test_misuse() -> None:
    with pytest.raises(SpoolError, match="positive"):
        MemoryBuffer(max_records=0)
    buffer = MemoryBuffer(max_bytes=10)
    with pytest.raises(SpoolError, match="exceeds"):
        buffer.append(b"x" * 11)
    with buffer:
        pass
    with pytest.raises(SpoolClosedError):
        buffer.append(b"x")
