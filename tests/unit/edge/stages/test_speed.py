"""Per-sample cost of the cheap stages: filter and throttle must stay far above 200,000 samples/s
on one core (compiled closures, no per-sample parsing). Best of three runs, to ride out noise."""

from __future__ import annotations

import time
from collections.abc import Callable

import pytest

from edge.stages import FilterStage, Sample, Stage, ThrottleStage
from tests.unit.edge.stages.messages import imu_value, sample

N = 20_000
TARGET = 200_000


def rate(make: Callable[[], Stage], samples: list[Sample]) -> float:
    best = 0.0
    for _ in range(3):
        stage = make()
        process = stage.process
        start = time.perf_counter()
        for i, item in enumerate(samples):
            process(item, i * 1000)
        best = max(best, len(samples) / (time.perf_counter() - start))
    return best


@pytest.mark.parametrize(
    ("label", "make"),
    [
        ("filter simple", lambda: FilterStage("linear_acceleration.x > 0.5")),
        (
            "filter compound",
            lambda: FilterStage(
                "linear_acceleration.x > 0.5 && abs(angular_velocity.z) < 1 || header.frame_id == 'base'"
            ),
        ),
        ("throttle first", lambda: ThrottleStage(10, "first")),
        ("throttle latest", lambda: ThrottleStage(10, "latest")),
    ],
)
def test_rate(label: str, make: Callable[[], Stage]) -> None:
    samples = [sample(imu_value(i, ax=(i % 100) / 100, wz=0.1)) for i in range(N)]
    measured = rate(make, samples)
    print(f"{label}: {measured:,.0f} samples/s")
    assert measured > TARGET
