"""fleetlink.common.metrics.buckets: latencies counted per bucket where they are measured."""

from __future__ import annotations

import pytest

from fleetlink.common.metrics.buckets import EMPTY, BucketCounts, BucketDeltas, BucketTotals
from fleetlink.common.metrics.families import LATENCY_BUCKETS

pytestmark = pytest.mark.unit


def test_each_value_lands_in_the_bucket_it_falls_in() -> None:
    counts = BucketCounts()
    for value in (0.0005, 0.001, 0.0011, 59.0, 61.0, -1.0):
        counts.observe(value)
    totals = counts.totals()
    assert len(totals.counts) == len(LATENCY_BUCKETS) + 1
    assert totals.counts[0] == 3  # 0.0005, 0.001 (upper bounds are inclusive) and -1 (as 0)
    assert totals.counts[1] == 1
    assert totals.counts[LATENCY_BUCKETS.index(60.0)] == 1
    assert totals.counts[-1] == 1  # above every bucket
    assert totals.count == 6
    assert totals.sum_s == pytest.approx(0.0005 + 0.001 + 0.0011 + 59 + 61)


def test_deltas_since_the_last_look_and_after_a_reset() -> None:
    deltas = BucketDeltas()
    first = BucketTotals((1, 2) + (0,) * (len(EMPTY.counts) - 2), 0.5)
    assert deltas.delta("durable", first) == first
    second = BucketTotals((1, 5) + (0,) * (len(EMPTY.counts) - 2), 0.8)
    step = deltas.delta("durable", second)
    assert step.counts[:2] == (0, 3)
    assert step.sum_s == pytest.approx(0.3)
    reset = BucketTotals((1,) + (0,) * (len(EMPTY.counts) - 1), 0.1)
    assert deltas.delta("durable", reset) == reset  # the sender was rebuilt: all of it is new
    assert deltas.delta("memory", EMPTY).count == 0
