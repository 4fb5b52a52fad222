"""Which offsets may be committed, when records finish out of order (pure, thread-safe).

Records of a partition are handed out in offset order but settle in any order (one site may
answer before another). The committable position of a partition is its lowest offset still in
flight, or one past the highest offset seen when none is: committing it never skips a record
that has not settled, so after a crash everything not settled comes again (at-least-once).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

TopicPartitionKey = tuple[str, int]


@dataclass
class _Partition:
    pending: dict[int, float] = field(default_factory=dict)
    """Offset -> when it was handed out (the tracker's clock)."""
    highest: int = -1
    committed: int = -1


class OffsetTracker:
    """The records in flight per partition, and the offsets that may be committed (thread-safe)."""

    def __init__(self, *, clock: Callable[[], float] = time.monotonic) -> None:
        self._parts: dict[TopicPartitionKey, _Partition] = {}
        self._lock = threading.Lock()
        self._clock = clock

    def begin(self, tp: TopicPartitionKey, offset: int) -> None:
        """Note the record at ``offset`` of ``tp`` as handed out and in flight."""
        now = self._clock()
        with self._lock:
            part = self._parts.setdefault(tp, _Partition())
            part.pending[offset] = now
            part.highest = max(part.highest, offset)

    def done(self, tp: TopicPartitionKey, offset: int) -> None:
        """Note the record at ``offset`` of ``tp`` as settled (ignored for a forgotten partition)."""
        with self._lock:
            part = self._parts.get(tp)
            if part is not None:
                part.pending.pop(offset, None)

    def in_flight(self) -> int:
        """How many records, over all partitions, are handed out and not settled."""
        with self._lock:
            return sum(len(p.pending) for p in self._parts.values())

    def oldest_age_s(self) -> float:
        """How long the oldest record still in flight has waited (0 when none is): the command lag."""
        now = self._clock()
        with self._lock:
            started = [t for p in self._parts.values() for t in p.pending.values()]
        return max(0.0, now - min(started)) if started else 0.0

    def committable(self) -> dict[TopicPartitionKey, int]:
        """Partition -> next offset to commit, for partitions that advanced since the last commit."""
        out: dict[TopicPartitionKey, int] = {}
        with self._lock:
            for tp, part in self._parts.items():
                position = min(part.pending) if part.pending else part.highest + 1
                if position > part.committed and position > 0:
                    out[tp] = position
        return out

    def committed(self, positions: dict[TopicPartitionKey, int]) -> None:
        """Note ``positions`` (partition -> offset) as committed to Kafka."""
        with self._lock:
            for tp, position in positions.items():
                part = self._parts.get(tp)
                if part is not None:
                    part.committed = max(part.committed, position)

    def forget(self, tps: list[TopicPartitionKey]) -> None:
        """Partitions revoked: their records are someone else's now."""
        with self._lock:
            for tp in tps:
                self._parts.pop(tp, None)
