"""The aggregate stage over the real Husky IMU bag, checked against numpy and the statistics
module computing the same windows from the raw data."""

from __future__ import annotations

import dataclasses
import io
import random
import statistics
from typing import Any

import fastavro
import numpy as np
import pytest
from rosbags.rosbag2 import Reader
from rosbags.typesys import Stores, get_typestore

from fleetlink.edge.stages import Sample, build_pipeline
from fleetlink.edge.stages.spec import AggregateSpec
from tests.paths import HUSKY
from tests.unit.edge.stages.messages import IMU_SCHEMA, schema

BAG = HUSKY
S = 1_000_000_000
FIELDS = ["linear_acceleration.x", "angular_velocity.z", "orientation_covariance[0]"]
OPS = ["count", "mean", "min", "max", "last", "stddev"]


def as_dict(msg: Any) -> Any:
    """A rosbags message -> the Avro-datum-shaped dict the edge decodes to (arrays stay numpy)."""
    if dataclasses.is_dataclass(msg):
        return {f.name: as_dict(getattr(msg, f.name)) for f in dataclasses.fields(msg)}
    return msg


@pytest.fixture(scope="module")
def imu_samples() -> list[Sample]:
    typestore = get_typestore(Stores.ROS2_HUMBLE)
    out = []
    with Reader(BAG) as reader:
        connections = [c for c in reader.connections if c.topic == "/imu/data"]
        for connection, _, raw in reader.messages(connections=connections):
            value = as_dict(typestore.deserialize_cdr(raw, connection.msgtype))
            stamp = value["header"]["stamp"]["sec"] * S + value["header"]["stamp"]["nanosec"]
            out.append(Sample("husky", "/imu/data", stamp, value, raw))
    return out


def reference(samples: list[Sample], window: int, hop: int) -> dict[int, dict[str, Any]]:
    """Every non-empty window computed directly: numpy over the stamps and values."""
    stamps = np.array([s.stamp_ns for s in samples], dtype=np.int64)
    columns = {
        "linear_acceleration_x": np.array([s.value["linear_acceleration"]["x"] for s in samples]),
        "angular_velocity_z": np.array([s.value["angular_velocity"]["z"] for s in samples]),
        "orientation_covariance_0": np.array([s.value["orientation_covariance"][0] for s in samples]),
    }
    first = (int(stamps.min()) - window) // hop * hop
    result = {}
    for start in range(first, int(stamps.max()) + 1, hop):
        inside = (stamps >= start) & (stamps < start + window)
        if not inside.any():
            continue
        last = int(np.flatnonzero(inside)[np.argmax(stamps[inside])])
        record: dict[str, Any] = {"count": int(inside.sum())}
        for name, column in columns.items():
            values = column[inside]
            record.update(
                {
                    f"{name}_count": len(values),
                    f"{name}_mean": float(values.mean()),
                    f"{name}_min": float(values.min()),
                    f"{name}_max": float(values.max()),
                    f"{name}_last": float(column[last]),
                    f"{name}_stddev": float(values.std()),
                }
            )
        result[start] = record
    return result


def run(samples: list[Sample], spec: dict[str, Any]) -> list[Sample]:
    pipeline = build_pipeline([AggregateSpec.model_validate({"type": "aggregate", **spec})])
    out: list[Sample] = []
    now = 0
    for item in samples:
        now = max(now, item.stamp_ns)  # processing time follows the robot's clock, as when live
        out += pipeline.process(item, now)
    out += pipeline.tick(now + 3600 * S)  # the robot went quiet: the idle timeout flushes the rest
    return out


def check(out: list[Sample], expected: dict[int, dict[str, Any]]) -> None:
    got = {s.value["window_start_ns"]: s.value for s in out}
    assert sorted(got) == sorted(expected)
    for start, ref in expected.items():
        record = got[start]
        for key, value in ref.items():
            assert record[key] == pytest.approx(value, rel=1e-9, abs=1e-12), (start, key)


@pytest.mark.parametrize(
    ("window", "hop"),
    [("1s", None), ("2s", "500ms"), ("10s", "10s")],
)
def test_windows_match_the_reference(imu_samples: list[Sample], window: str, hop: str | None) -> None:
    spec = {"window": window, "hop": hop, "fields": FIELDS, "ops": OPS}
    out = run(imu_samples, spec)
    window_ns = AggregateSpec.model_validate({"type": "aggregate", **spec}).window
    hop_ns = window_ns if hop is None else AggregateSpec.model_validate({"type": "aggregate", **spec}).hop
    assert hop_ns is not None
    expected = reference(imu_samples, window_ns, hop_ns)
    assert len(expected) > 30
    check(out, expected)
    # emitted in time order, one record per window, each encodable with the derived schema
    starts = [s.value["window_start_ns"] for s in out]
    assert starts == sorted(starts)
    derived = build_pipeline([AggregateSpec.model_validate({"type": "aggregate", **spec})]).output_schema(
        schema(IMU_SCHEMA)
    )
    parsed = fastavro.parse_schema(derived)
    buf = io.BytesIO()
    for item in out:
        fastavro.schemaless_writer(buf, parsed, item.value)
    assert buf.tell() > 0


def test_one_window_against_the_statistics_module(imu_samples: list[Sample]) -> None:
    out = run(imu_samples, {"window": "1s", "fields": ["linear_acceleration.x"], "ops": OPS})
    record = out[len(out) // 2].value
    start, end = record["window_start_ns"], record["window_end_ns"]
    values = [s.value["linear_acceleration"]["x"] for s in imu_samples if start <= s.stamp_ns < end]
    assert record["count"] == len(values) > 20
    assert record["linear_acceleration_x_mean"] == pytest.approx(statistics.fmean(values), rel=1e-12)
    assert record["linear_acceleration_x_stddev"] == pytest.approx(statistics.pstdev(values), rel=1e-9)
    assert record["linear_acceleration_x_min"] == min(values)
    assert record["linear_acceleration_x_max"] == max(values)
    assert record["linear_acceleration_x_last"] == values[-1]


def test_out_of_order_within_the_allowed_lateness_gives_the_same_windows(imu_samples: list[Sample]) -> None:
    shuffled = list(imu_samples)
    rng = random.Random(7)
    for i in range(0, len(shuffled) - 8, 8):  # reorder blocks of 8 samples (about 270 ms of data)
        block = shuffled[i : i + 8]
        rng.shuffle(block)
        shuffled[i : i + 8] = block
    spec = {"window": "1s", "fields": FIELDS, "ops": OPS, "allowed_lateness": "500ms"}
    out = run(shuffled, spec)
    check(out, reference(imu_samples, S, S))


def test_without_lateness_reordered_samples_are_counted_late(imu_samples: list[Sample]) -> None:
    swapped = list(imu_samples)
    second = [item.stamp_ns // S for item in swapped]
    # the last sample of a second arrives just after the first sample of the next second (where both
    # seconds have more samples around the boundary, so each move makes exactly one late sample)
    boundaries = [
        i
        for i in range(2, len(swapped) - 1)
        if second[i] != second[i - 1] and second[i - 2] == second[i - 1] and second[i + 1] == second[i]
    ]
    for i in boundaries:
        swapped[i - 1], swapped[i] = swapped[i], swapped[i - 1]
    late = len(boundaries)
    pipeline = build_pipeline(
        [
            AggregateSpec.model_validate(
                {"type": "aggregate", "window": "1s", "fields": FIELDS, "ops": ["count"]}
            )
        ]
    )
    for item in swapped:
        pipeline.process(item, item.stamp_ns)
    stage = pipeline.stages[0]
    assert stage.counters.late == late > 300
    assert stage.counters.passed == len(swapped) - late
    assert stage.counters.emitted == len(set(second)) - 1  # every window but the last, still open
