"""Per-sample cost of the edge stages on one core (compiled closures, no per-sample parsing).

Prints samples/s for filter, throttle, on_change and aggregate over Imu-shaped samples, best
of three runs, next to a reference in the same run: the same filter hand-written in Python
(a dict walk and a comparison in a list comprehension), the ceiling a compiled user
expression can approach.

    .venv/bin/python bench/bench_stages.py
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np
from pydantic import TypeAdapter

from fleetlink.edge.stages import FilterStage, Sample, Stage, ThrottleStage, build_stage
from fleetlink.edge.stages.spec import StageSpec

N = 20_000


def imu_value(stamp_ns: int, ax: float, wz: float) -> dict[str, Any]:
    zero = np.zeros(9)
    sec, nanosec = divmod(stamp_ns, 1_000_000_000)
    return {
        "header": {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": "imu_link"},
        "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
        "orientation_covariance": zero,
        "angular_velocity": {"x": 0.0, "y": 0.0, "z": wz},
        "angular_velocity_covariance": zero,
        "linear_acceleration": {"x": ax, "y": 0.0, "z": 9.81},
        "linear_acceleration_covariance": zero,
    }


def sample(value: dict[str, Any], stamp_ns: int) -> Sample:
    return Sample("tb4_01", "/tb4_01/imu", stamp_ns, value)


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


def naive_filter_rate(samples: list[Sample]) -> float:
    def get(value: Any, path: str) -> Any:
        for part in path.split("."):
            value = value[part]
        return value

    best = 0.0
    for _ in range(3):
        start = time.perf_counter()
        kept = [s for s in samples if get(s.value, "linear_acceleration.x") > 0.5]
        best = max(best, len(samples) / (time.perf_counter() - start))
        assert kept is not None
    return best


def spec(data: dict[str, Any]) -> StageSpec:
    adapter: TypeAdapter[StageSpec] = TypeAdapter(StageSpec)
    return adapter.validate_python(data)


def main() -> None:
    step = 10_000_000
    samples = [sample(imu_value(i * step, ax=(i % 100) / 100, wz=0.1), i * step) for i in range(N)]
    cases: list[tuple[str, Callable[[], Stage]]] = [
        ("filter simple", lambda: FilterStage("linear_acceleration.x > 0.5")),
        (
            "filter compound",
            lambda: FilterStage(
                "linear_acceleration.x > 0.5 && abs(angular_velocity.z) < 1 || header.frame_id == 'base'"
            ),
        ),
        ("throttle first", lambda: ThrottleStage(10, "first")),
        ("throttle latest", lambda: ThrottleStage(10, "latest")),
        (
            "on_change",
            lambda: build_stage(
                spec(
                    {
                        "type": "on_change",
                        "fields": ["linear_acceleration.x"],
                        "deadband": 0.05,
                        "heartbeat": "5s",
                    }
                )
            ),
        ),
        (
            "aggregate 2x6",
            lambda: build_stage(
                spec(
                    {
                        "type": "aggregate",
                        "window": "1s",
                        "fields": ["linear_acceleration.x", "angular_velocity.z"],
                        "ops": ["count", "mean", "min", "max", "last", "stddev"],
                    }
                )
            ),
        ),
    ]
    baseline = naive_filter_rate(samples)
    print(f"{'stage':<18} {'samples/s':>12}")
    print(f"{'hand-written':<18} {baseline:>12,.0f}   (reference: the filter hand-coded in Python)")
    for label, make in cases:
        measured = rate(make, samples)
        ratio = measured / baseline
        extra = f"   ({ratio:.2f}x hand-written)" if label.startswith("filter") else ""
        print(f"{label:<18} {measured:>12,.0f}{extra}")


if __name__ == "__main__":
    main()
