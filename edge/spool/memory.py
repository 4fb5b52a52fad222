"""The memory buffer for ``best_effort`` mappings: the spool's interface, in RAM, bounded.

Nothing survives a restart. When full it drops the oldest records that are not in flight
(released batches first, whole, then unread groups one by one), counting each record in
``dropped_oldest``; if everything held is in flight, the new group is dropped
(``dropped_newest``). Seqs start at the wall clock in microseconds, so a restarted edge never
re-uses a seq of this stream while it stays under a million records a second.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable, Sequence

from fleetlink.edge.errors import SpoolClosedError, SpoolError
from fleetlink.edge.spool.api import SpoolBatch, SpoolGroup, SpoolStats
from fleetlink.edge.spool.grouping import pack_groups
from fleetlink.edge.spool.spool import wall_ms
from fleetlink.wire.groups import group_count, split_group


class MemoryBuffer:
    """A ``RecordBuffer`` in memory, holding groups of records. Thread-safe."""

    def __init__(
        self,
        *,
        stream: str = "memory",
        max_bytes: int = 64 << 20,
        max_records: int = 100_000,
        clock: Callable[[], int] = wall_ms,
        first_seq: int | None = None,
        group_records: int = 2000,
        group_bytes: int = 1 << 20,
    ) -> None:
        if max_bytes < 1 or max_records < 1 or group_records < 1 or group_bytes < 1:
            raise SpoolError("max_bytes, max_records and the group limits must be positive")
        self._stream = stream
        self._max_bytes = max_bytes
        self._max_records = max_records
        self._group_records = group_records
        self._group_bytes = group_bytes
        self._clock = clock
        self._lock = threading.Lock()
        self._next_seq = time.time_ns() // 1000 if first_seq is None else first_seq
        self._pending: deque[SpoolGroup] = deque()
        self._in_flight: dict[int, tuple[SpoolGroup, ...]] = {}
        self._retry: dict[int, tuple[SpoolGroup, ...]] = {}
        self._bytes = 0
        self._records = 0
        self._closed = False
        self._c = {"appended": 0, "acked": 0, "dropped_oldest": 0, "dropped_newest": 0, "stale_acks": 0}

    @property
    def stream(self) -> str:
        """The stream's name."""
        return self._stream

    def open(self) -> MemoryBuffer:
        """Nothing to open in memory; returns ``self`` (for symmetry with ``Spool.open``)."""
        return self

    def close(self) -> None:
        """Close the buffer: later calls raise ``SpoolClosedError``; what it held is gone."""
        self._closed = True

    def __enter__(self) -> MemoryBuffer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _check_open(self) -> None:
        if self._closed:
            raise SpoolClosedError(f"memory buffer {self._stream!r} is closed")

    def append(self, payload: bytes) -> int | None:
        """Take one record; returns its seq, or ``None`` when it was dropped because everything held is in
        flight."""
        return self.append_many((payload,))[0]

    def append_many(self, payloads: Sequence[bytes]) -> list[int | None]:
        """``append`` for several records, packed into groups; raises ``SpoolError`` when a record is
        larger than the buffer."""
        for payload in payloads:
            if len(payload) > self._max_bytes:
                raise SpoolError(
                    f"record of {len(payload)} bytes exceeds the buffer ({self._max_bytes} bytes)"
                )
        out: list[int | None] = []
        for group, count in pack_groups(payloads, self._group_records, self._group_bytes):
            first = self._take(group, count)
            out.extend([None] * count if first is None else range(first, first + count))
        return out

    def append_group(self, group: bytes) -> int:
        """Take a group made elsewhere (split to the buffer's group limits); returns the records taken, the
        rest dropped (counted)."""
        return self.append_groups((group,))

    def append_groups(self, groups: Sequence[bytes]) -> int:
        """``append_group`` for several groups, in order; raises ``SpoolError`` (nothing taken) when
        one is larger than the buffer."""
        parts = [
            part for group in groups for part in split_group(group, self._group_records, self._group_bytes)
        ]
        for part in parts:
            if len(part) > self._max_bytes:
                raise SpoolError(f"group of {len(part)} bytes exceeds the buffer ({self._max_bytes} bytes)")
        taken = 0
        for part in parts:
            count = group_count(part)
            if self._take(part, count) is not None:
                taken += count
        return taken

    def _take(self, group: bytes, count: int) -> int | None:
        """Keep one group; its first seq, or None when it was dropped (counted)."""
        with self._lock:
            self._check_open()
            if not self._make_room(len(group), count):
                self._c["dropped_newest"] += count
                return None
            first = self._next_seq
            self._next_seq += count
            self._pending.append(SpoolGroup(first, count, self._clock(), group))
            self._bytes += len(group)
            self._records += count
            self._c["appended"] += count
            return first

    def _make_room(self, size: int, count: int) -> bool:
        while self._bytes + size > self._max_bytes or self._records + count > self._max_records:
            if self._retry:
                self._forget(self._retry.pop(min(self._retry)), "dropped_oldest")
            elif self._pending:
                self._forget((self._pending.popleft(),), "dropped_oldest")
            else:
                return False
        return True

    def _forget(self, groups: tuple[SpoolGroup, ...], counter: str) -> None:
        self._bytes -= sum(len(g.group) for g in groups)
        records = sum(g.records for g in groups)
        self._records -= records
        self._c[counter] += records

    def read_unacked(
        self, max_records: int = 500, max_bytes: int = 1 << 20, *, skip_in_flight: bool = True
    ) -> SpoolBatch | None:
        """The next batch to send (released batches first, then unread groups), marked in flight; ``None``
        when there is nothing to send. ``skip_in_flight=False`` first releases everything in flight."""
        if max_records < 1 or max_bytes < 1:
            raise SpoolError("max_records and max_bytes must be positive")
        with self._lock:
            self._check_open()
            if not skip_in_flight:
                self._retry.update(self._in_flight)
                self._in_flight.clear()
            if self._retry:
                groups = self._retry.pop(min(self._retry))
            else:
                taken: list[SpoolGroup] = []
                total = records = 0
                while self._pending:
                    head = self._pending[0]
                    if taken and (
                        records + head.records > max_records or total + len(head.group) > max_bytes
                    ):
                        break
                    taken.append(self._pending.popleft())
                    total += len(head.group)
                    records += head.records
                if not taken:
                    return None
                groups = tuple(taken)
            self._in_flight[groups[0].first_seq] = groups
            return SpoolBatch(self._stream, groups[0].first_seq, groups[-1].last_seq, groups)

    def ack(self, first_seq: int) -> bool:
        """The batch starting at ``first_seq`` reached Kafka: forget it; False if unknown (stale, counted)."""
        with self._lock:
            self._check_open()
            groups = self._in_flight.pop(first_seq, None) or self._retry.pop(first_seq, None)
            if groups is None:
                self._c["stale_acks"] += 1
                return False
            self._forget(groups, "acked")
            return True

    def release(self, first_seq: int) -> bool:
        """The batch starting at ``first_seq`` must be sent again; False if it is not in flight."""
        with self._lock:
            self._check_open()
            groups = self._in_flight.pop(first_seq, None)
            if groups is None:
                return False
            self._retry[first_seq] = groups
            return True

    def release_all(self) -> int:
        """Everything in flight must be sent again; returns how many batches that was."""
        with self._lock:
            self._check_open()
            count = len(self._in_flight)
            self._retry.update(self._in_flight)
            self._in_flight.clear()
            return count

    def note_marks(self, marks: bytes) -> None:
        """Nothing survives a restart here: marks are not kept."""

    def unsent(self) -> int:
        """Records held and not in flight (what ``read_unacked`` may still hand out)."""
        with self._lock:
            in_flight = sum(g.records for groups in self._in_flight.values() for g in groups)
            return max(0, self._records - in_flight)

    def stats(self) -> SpoolStats:
        """Counters since creation and what the buffer holds now (the disk and blocking counters stay 0)."""
        with self._lock:
            heads = [g[0].timestamp_ms for g in (*self._in_flight.values(), *self._retry.values())]
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
                in_flight=sum(g.records for groups in self._in_flight.values() for g in groups),
                oldest_append_ms=min(heads, default=None),
                segments=0,
                next_seq=self._next_seq,
            )
