"""Latencies counted where they are measured, reported when someone looks (pure; thread-safe).

A component on a hot path (the edge's WAN sender) keeps a ``BucketCounts``: ``observe(seconds)``
adds one to the bucket of ``LATENCY_BUCKETS`` it falls in. A reader (the edge's telemetry)
takes ``totals()`` now and then and reports the increase since its previous look with
``Metrics.on_ack_latencies`` (``BucketDeltas``), so the Prometheus histogram is filled without
the sender knowing about metrics.
"""

from __future__ import annotations

import bisect
import threading
from dataclasses import dataclass

from fleetlink.common.metrics.families import LATENCY_BUCKETS


@dataclass(frozen=True, slots=True)
class BucketTotals:
    """Latency observations counted per bucket of ``LATENCY_BUCKETS`` and their sum in seconds."""

    counts: tuple[int, ...]
    """Observations per bucket (not cumulative): ``LATENCY_BUCKETS`` then one above them all."""
    sum_s: float

    @property
    def count(self) -> int:
        """The number of observations in all buckets."""
        return sum(self.counts)

    def as_dict(self) -> dict[str, object]:
        """The totals as JSON-ready data: the per-bucket counts and the sum rounded to microseconds."""
        return {"counts": list(self.counts), "sum_s": round(self.sum_s, 6)}


EMPTY = BucketTotals(counts=(0,) * (len(LATENCY_BUCKETS) + 1), sum_s=0.0)


class BucketCounts:
    """Running latency counts per bucket, added to on a hot path and read as ``BucketTotals``; thread-safe."""

    def __init__(self) -> None:
        self._counts = [0] * (len(LATENCY_BUCKETS) + 1)
        self._sum = 0.0
        self._lock = threading.Lock()

    def observe(self, seconds: float) -> None:
        """Count one latency of ``seconds`` (negative as 0) in the bucket it falls in."""
        value = max(0.0, seconds)
        index = bisect.bisect_left(LATENCY_BUCKETS, value)
        with self._lock:
            self._counts[index] += 1
            self._sum += value

    def totals(self) -> BucketTotals:
        """A snapshot of the counts and sum observed so far."""
        with self._lock:
            return BucketTotals(tuple(self._counts), self._sum)


class BucketDeltas:
    """The increase of several ``BucketTotals`` since the previous look, by key (a total that
    went down was reset: all of it is new)."""

    def __init__(self) -> None:
        self._last: dict[str, BucketTotals] = {}

    def delta(self, key: str, now: BucketTotals) -> BucketTotals:
        """The increase of ``key``'s totals since the previous call for it (all of ``now`` after a reset)."""
        before = self._last.get(key, EMPTY)
        self._last[key] = now
        if now.count < before.count or len(now.counts) != len(before.counts):
            return now
        return BucketTotals(
            tuple(a - b for a, b in zip(now.counts, before.counts, strict=True)),
            max(0.0, now.sum_s - before.sum_s),
        )
