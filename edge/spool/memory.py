"""The memory buffer for ``best_effort`` mappings: the spool's interface, in RAM, bounded.

Nothing survives a restart. When full it drops the oldest records that are not in flight
(released batches first, whole, then unread records one by one), counting each in
``dropped_oldest``; if everything held is in flight, the new record is dropped
(``dropped_newest``). Seqs start at the wall clock in microseconds, so a restarted edge never
re-uses a seq of this stream while it stays under a million records a second.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable, Sequence

from fleetlink.edge.errors import SpoolClosedError, SpoolError
from fleetlink.edge.spool.api import SpoolBatch, SpoolRecord, SpoolStats
from fleetlink.edge.spool.spool import wall_ms


class MemoryBuffer:
    """A ``RecordBuffer`` in memory. Thread-safe."""

    def __init__(
        self,
        *,
        stream: str = "memory",
        max_bytes: int = 64 << 20,
        max_records: int = 100_000,
        clock: Callable[[], int] = wall_ms,
        first_seq: int | None = None,
    ) -> None:
        if max_bytes < 1 or max_records < 1:
            raise SpoolError("max_bytes and max_records must be positive")
        self._stream = stream
        self._max_bytes = max_bytes
        self._max_records = max_records
        self._clock = clock
        self._lock = threading.Lock()
        self._next_seq = time.time_ns() // 1000 if first_seq is None else first_seq
        self._pending: deque[SpoolRecord] = deque()
        self._in_flight: dict[int, tuple[SpoolRecord, ...]] = {}
        self._retry: dict[int, tuple[SpoolRecord, ...]] = {}
        self._bytes = 0
        self._records = 0
        self._closed = False
        self._c = {"appended": 0, "acked": 0, "dropped_oldest": 0, "dropped_newest": 0, "stale_acks": 0}

    @property
    def stream(self) -> str:
        return self._stream

    def open(self) -> MemoryBuffer:
        return self

    def close(self) -> None:
        self._closed = True

    def __enter__(self) -> MemoryBuffer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _check_open(self) -> None:
        if self._closed:
            raise SpoolClosedError(f"memory buffer {self._stream!r} is closed")

    def append(self, payload: bytes) -> int | None:
        return self.append_many((payload,))[0]

    def append_many(self, payloads: Sequence[bytes]) -> list[int | None]:
        for payload in payloads:
            if len(payload) > self._max_bytes:
                raise SpoolError(
                    f"record of {len(payload)} bytes exceeds the buffer ({self._max_bytes} bytes)"
                )
        out: list[int | None] = []
        with self._lock:
            self._check_open()
            for payload in payloads:
                if not self._make_room(len(payload)):
                    self._c["dropped_newest"] += 1
                    out.append(None)
                    continue
                seq = self._next_seq
                self._next_seq += 1
                self._pending.append(SpoolRecord(seq, self._clock(), payload))
                self._bytes += len(payload)
                self._records += 1
                self._c["appended"] += 1
                out.append(seq)
        return out

    def _make_room(self, size: int) -> bool:
        while self._bytes + size > self._max_bytes or self._records + 1 > self._max_records:
            if self._retry:
                self._forget(self._retry.pop(min(self._retry)), "dropped_oldest")
            elif self._pending:
                self._forget((self._pending.popleft(),), "dropped_oldest")
            else:
                return False
        return True

    def _forget(self, records: tuple[SpoolRecord, ...], counter: str) -> None:
        self._bytes -= sum(len(r.payload) for r in records)
        self._records -= len(records)
        self._c[counter] += len(records)

    def read_unacked(
        self, max_records: int = 500, max_bytes: int = 1 << 20, *, skip_in_flight: bool = True
    ) -> SpoolBatch | None:
        if max_records < 1 or max_bytes < 1:
            raise SpoolError("max_records and max_bytes must be positive")
        with self._lock:
            self._check_open()
            if not skip_in_flight:
                self._retry.update(self._in_flight)
                self._in_flight.clear()
            if self._retry:
                records = self._retry.pop(min(self._retry))
            else:
                taken: list[SpoolRecord] = []
                total = 0
                while self._pending and len(taken) < max_records:
                    size = len(self._pending[0].payload)
                    if taken and total + size > max_bytes:
                        break
                    taken.append(self._pending.popleft())
                    total += size
                if not taken:
                    return None
                records = tuple(taken)
            self._in_flight[records[0].seq] = records
            return SpoolBatch(self._stream, records[0].seq, records[-1].seq, records)

    def ack(self, first_seq: int) -> bool:
        with self._lock:
            self._check_open()
            records = self._in_flight.pop(first_seq, None) or self._retry.pop(first_seq, None)
            if records is None:
                self._c["stale_acks"] += 1
                return False
            self._forget(records, "acked")
            return True

    def release(self, first_seq: int) -> bool:
        with self._lock:
            self._check_open()
            records = self._in_flight.pop(first_seq, None)
            if records is None:
                return False
            self._retry[first_seq] = records
            return True

    def release_all(self) -> int:
        with self._lock:
            self._check_open()
            count = len(self._in_flight)
            self._retry.update(self._in_flight)
            self._in_flight.clear()
            return count

    def stats(self) -> SpoolStats:
        with self._lock:
            heads = [r[0].timestamp_ms for r in (*self._in_flight.values(), *self._retry.values())]
            if self._pending:
                heads.append(self._pending[0].timestamp_ms)
            return SpoolStats(
                stream=self._stream,
                corrupt_skipped=0,
                block_timeouts=0,
                disk_full=0,
                fsyncs=0,
                **self._c,
                bytes=self._bytes,
                depth=self._records,
                in_flight=sum(len(r) for r in self._in_flight.values()),
                oldest_append_ms=min(heads, default=None),
                segments=0,
                next_seq=self._next_seq,
            )
