"""fleetlink.uplink.latency: Kafka delivery latency per site over a window (clock injected)."""

from __future__ import annotations

import pytest

from fleetlink.uplink.latency import DeliveryLatency, percentile


@pytest.mark.parametrize(
    ("values", "q", "expected"),
    [
        ([1.0], 0.5, 1.0),
        ([1.0, 2.0], 0.5, 1.0),
        ([1.0, 2.0, 3.0], 0.5, 2.0),
        ([1.0, 2.0, 3.0, 4.0], 0.95, 4.0),
        ([float(i) for i in range(1, 101)], 0.95, 95.0),
        ([float(i) for i in range(1, 101)], 0.0, 1.0),
    ],
)
def test_percentile_by_nearest_rank(values: list[float], q: float, expected: float) -> None:
    assert percentile(values, q) == expected


def test_percentile_of_nothing_is_an_error() -> None:
    with pytest.raises(ValueError, match="no values"):
        percentile([], 0.5)


def test_summary_over_the_window_per_site() -> None:
    now = [0.0]
    latency = DeliveryLatency(window_s=60.0, clock=lambda: now[0])
    assert latency.summary("a") is None
    for seconds in (0.010, 0.020, 0.030, 0.500):
        latency.observe("a", seconds)
    latency.observe("b", -1.0)  # a clock step: never negative
    assert latency.summary("a") == {
        "batches": 4,
        "p50_ms": 20.0,
        "p95_ms": 500.0,
        "max_ms": 500.0,
        "window_s": 60.0,
    }
    assert latency.summary("b") == {
        "batches": 1,
        "p50_ms": 0.0,
        "p95_ms": 0.0,
        "max_ms": 0.0,
        "window_s": 60.0,
    }
    now[0] = 30.0
    latency.observe("a", 0.040)
    now[0] = 61.0  # the first four left the window
    assert latency.summary("a") == {
        "batches": 1,
        "p50_ms": 40.0,
        "p95_ms": 40.0,
        "max_ms": 40.0,
        "window_s": 60.0,
    }
    now[0] = 200.0
    assert latency.summary("a") is None
    assert latency.sites() == ["a", "b"]


def test_memory_is_bounded() -> None:
    latency = DeliveryLatency(max_samples=3, clock=lambda: 0.0)
    for ms in (900, 800, 1, 2, 3):
        latency.observe("a", ms / 1000)
    summary = latency.summary("a")
    assert summary is not None
    assert (summary["batches"], summary["max_ms"]) == (3, 3.0)
