"""The aggregate stage: window boundaries, watermarks, late samples, NaN, empty windows, idle
timeout, output records and their derived schema."""

from __future__ import annotations

import io
import math
import statistics
from typing import Any

import fastavro
import pytest

from fleetlink.edge.stages import AggregateStage, FieldPathError, Sample, StageConfigError
from fleetlink.edge.stages.windows import RunningStats, window_starts
from tests.unit.edge.stages.messages import IMU_SCHEMA, STATUS_SCHEMA, sample, schema

MS = 1_000_000
S = 1_000_000_000
T0 = 1_700_000_000 * S  # a realistic, second-aligned epoch time
ALL_OPS = ["count", "mean", "min", "max", "last", "stddev"]


@pytest.mark.parametrize(
    ("stamp", "size", "hop", "starts"),
    [
        (0, 10, 10, [0]),
        (9, 10, 10, [0]),
        (10, 10, 10, [10]),
        (25, 10, 10, [20]),
        (25, 20, 10, [10, 20]),
        (20, 20, 10, [10, 20]),
        (19, 20, 10, [0, 10]),
        (25, 30, 10, [0, 10, 20]),
        (25, 25, 10, [10, 20]),
        (35, 25, 10, [20, 30]),
        (30, 25, 10, [10, 20, 30]),
    ],
)
def test_window_starts(stamp: int, size: int, hop: int, starts: list[int]) -> None:
    got = list(window_starts(stamp, size, hop))
    assert got == starts
    assert all(s <= stamp < s + size for s in got)


@pytest.mark.parametrize(
    "values",
    [[1.0], [1.0, 2.0, 3.0, 4.0], [5.5, -2.25, 1e6, 3.0, 3.0], [1e9 + 1, 1e9 + 2, 1e9 + 3]],
)
def test_running_stats_match_statistics(values: list[float]) -> None:
    stats = RunningStats()
    for i, v in enumerate(values):
        stats.add(v, i)
    assert stats.result("count") == len(values)
    assert stats.result("mean") == pytest.approx(statistics.fmean(values), rel=1e-12)
    assert stats.result("min") == min(values)
    assert stats.result("max") == max(values)
    assert stats.result("last") == values[-1]
    assert stats.result("stddev") == pytest.approx(statistics.pstdev(values), rel=1e-9, abs=1e-12)


def test_running_stats_without_values() -> None:
    stats = RunningStats()
    assert [stats.result(op) for op in ALL_OPS] == [0, None, None, None, None, None]
    with pytest.raises(ValueError, match="unknown statistic"):
        stats.result("median")


def make(
    window_ms: int = 1000,
    hop_ms: int | None = None,
    lateness_ms: int = 0,
    idle_ms: int | None = None,
    ops: list[str] | None = None,
) -> AggregateStage:
    return AggregateStage(
        ["x"],
        ops or ALL_OPS,
        window_ms * MS,
        hop_ns=None if hop_ms is None else hop_ms * MS,
        allowed_lateness_ns=lateness_ms * MS,
        idle_timeout_ns=None if idle_ms is None else idle_ms * MS,
    )


def feed(stage: AggregateStage, rows: list[tuple[int, float]], robot: str = "tb4_01") -> list[Sample]:
    """rows: (stamp in ms after T0, x); processing time = event time (a live robot)."""
    out: list[Sample] = []
    for stamp_ms, x in rows:
        stamp = T0 + stamp_ms * MS
        out += stage.process(sample({"x": x}, robot=robot, topic=f"/{robot}/imu", stamp_ns=stamp), stamp)
    return out


def windows(out: list[Sample]) -> list[tuple[int, int, int]]:
    """(start ms, end ms, count) of each emitted record, relative to T0."""
    return [
        ((s.value["window_start_ns"] - T0) // MS, (s.value["window_end_ns"] - T0) // MS, s.value["count"])
        for s in out
    ]


@pytest.mark.parametrize(
    ("rows", "emitted"),
    [
        # a window closes when a stamp at or past its end arrives (watermark reaches the end)
        ([(0, 1), (500, 2), (999, 3)], []),
        ([(0, 1), (500, 2), (999, 3), (1000, 4)], [(0, 1000, 3)]),
        # empty windows emit nothing
        ([(100, 1), (3500, 2)], [(0, 1000, 1)]),
        ([(100, 1), (1100, 2), (2100, 3), (3100, 4)], [(0, 1000, 1), (1000, 2000, 1), (2000, 3000, 1)]),
        # out of order inside the open window is fine
        ([(900, 1), (100, 2), (500, 3), (1200, 4)], [(0, 1000, 3)]),
    ],
)
def test_tumbling_boundaries(rows: list[tuple[int, float]], emitted: list[tuple[int, int, int]]) -> None:
    stage = make()
    assert windows(feed(stage, rows)) == emitted
    assert stage.counters.late == 0


def test_record_values() -> None:
    stage = make()
    out = feed(stage, [(0, 1.0), (200, 4.0), (900, -2.0), (500, 3.0), (1000, 0.0)])
    assert len(out) == 1
    record = out[0].value
    values = [1.0, 4.0, -2.0, 3.0]
    assert record["robot"] == "tb4_01"
    assert record["window_start_ns"] == T0
    assert record["window_end_ns"] == T0 + S
    assert record["count"] == 4
    assert record["x_count"] == 4
    assert record["x_mean"] == pytest.approx(statistics.fmean(values))
    assert record["x_min"] == -2.0
    assert record["x_max"] == 4.0
    assert record["x_last"] == -2.0  # greatest stamp (900 ms), not the last to arrive (500 ms)
    assert record["x_stddev"] == pytest.approx(statistics.pstdev(values))
    assert out[0].stamp_ns == T0 + S
    assert out[0].topic == "/tb4_01/imu"
    assert out[0].raw is None


@pytest.mark.parametrize(
    ("lateness_ms", "rows", "emitted", "late"),
    [
        # no lateness: once [0,1000) is out, a sample for it is late
        (0, [(100, 1), (1000, 2), (900, 3), (999, 4), (1500, 5)], [(0, 1000, 1)], 2),
        # 500 ms allowed: the window waits for stamp 1500, so 900 is still counted
        (500, [(100, 1), (1200, 2), (900, 3), (1500, 4), (950, 5), (2000, 6)], [(0, 1000, 2)], 1),
        # lateness spanning several windows: all emitted in order when the watermark moves
        (2000, [(100, 1), (1100, 2), (2100, 3), (3100, 4), (4100, 5)], [(0, 1000, 1), (1000, 2000, 1)], 0),
        # a sample older than every open window, before anything was emitted, is late too
        (0, [(5000, 1), (4000, 2)], [], 1),
    ],
)
def test_late_samples(
    lateness_ms: int, rows: list[tuple[int, float]], emitted: list[tuple[int, int, int]], late: int
) -> None:
    stage = make(lateness_ms=lateness_ms)
    assert windows(feed(stage, rows)) == emitted
    assert stage.counters.late == late
    c = stage.counters
    assert c.received == c.passed + c.late + c.errors


def test_hopping_windows_count_each_sample_in_every_window() -> None:
    stage = make(window_ms=2000, hop_ms=1000)
    out = feed(stage, [(500, 1.0), (1500, 2.0), (2500, 3.0), (3000, 4.0), (4000, 0.0)])
    assert windows(out) == [(-1000, 1000, 1), (0, 2000, 2), (1000, 3000, 2), (2000, 4000, 2)]
    means = [s.value["x_mean"] for s in out]
    assert means == [1.0, 1.5, 2.5, 3.5]


def test_nan_values_are_skipped_and_counted() -> None:
    stage = make()
    out = feed(
        stage, [(0, 1.0), (100, math.nan), (200, 3.0), (1000, math.nan), (1100, math.nan), (2000, 5.0)]
    )
    first, second = (s.value for s in out)
    assert (first["count"], first["x_count"], first["x_mean"], first["x_min"], first["x_max"]) == (
        3,
        2,
        2.0,
        1,
        3,
    )
    assert first["x_last"] == 3.0
    # a window of NaN only: samples counted, every statistic null
    assert (second["count"], second["x_count"]) == (2, 0)
    assert [second[f"x_{op}"] for op in ALL_OPS[1:]] == [None] * 5
    assert stage.counters.nan == 3
    assert stage.counters.passed == 6


def test_infinities_propagate() -> None:
    stage = make()
    record = feed(stage, [(0, 1.0), (100, math.inf), (1000, 0.0)])[0].value
    assert record["x_max"] == math.inf
    assert record["x_mean"] == math.inf
    assert math.isnan(record["x_stddev"])


def test_idle_timeout_flushes_on_processing_time_then_closes_those_windows() -> None:
    stage = make(idle_ms=3000)
    assert windows(feed(stage, [(100, 1.0), (1200, 2.0), (1300, 3.0)])) == [(0, 1000, 1)]
    # last arrival at processing time T0 + 1300 ms; the window [1000, 2000) waits for a stamp
    assert stage.tick(T0 + 4299 * MS) == []
    out = stage.tick(T0 + 4300 * MS)
    assert windows(out) == [(1000, 2000, 2)]
    assert stage.tick(T0 + 10_000 * MS) == []  # nothing twice
    assert stage.open_windows == 0
    # the robot comes back with an old stamp: its window was already emitted
    assert feed(stage, [(1900, 3.0)]) == []
    assert stage.counters.late == 1
    assert windows(feed(stage, [(2100, 4.0), (3000, 0.0)])) == [(2000, 3000, 1)]


def test_default_idle_timeout_is_window_plus_lateness() -> None:
    stage = make(window_ms=1000, lateness_ms=500)
    feed(stage, [(100, 1.0)])
    assert stage.tick(T0 + 1599 * MS) == []
    assert len(stage.tick(T0 + 1600 * MS)) == 1


def test_robots_have_their_own_windows_and_watermarks() -> None:
    stage = make()
    feed(stage, [(100, 1.0), (5000, 1.0)], robot="fast")
    out = feed(stage, [(200, 2.0), (300, 4.0)], robot="slow")  # not late: its own watermark
    assert out == []
    out = feed(stage, [(1000, 0.0)], robot="slow")
    assert [(s.robot, s.value["robot"], s.value["x_mean"]) for s in out] == [("slow", "slow", 3.0)]


@pytest.mark.parametrize(
    ("value", "error"),
    [({"x": "3"}, "TypeError"), ({"x": True}, "TypeError"), ({}, "KeyError"), ({"x": None}, "TypeError")],
)
def test_bad_values_are_counted_as_errors(value: dict[str, Any], error: str) -> None:
    stage = make()
    assert stage.process(sample(value, stamp_ns=T0), T0) == []
    assert stage.counters.errors == 1
    assert stage.open_windows == 0
    assert stage.last_error is not None
    assert stage.last_error.startswith(error)


def test_output_schema_and_records_match() -> None:
    stage = AggregateStage(
        ["linear_acceleration.x", "orientation_covariance[0]"], ["count", "mean", "stddev"], S
    )
    derived = stage.output_schema(schema(IMU_SCHEMA))
    assert derived["namespace"] == "fleetlink.agg"
    assert derived["name"].startswith("Imu_")
    assert [f["name"] for f in derived["fields"]] == [
        "robot",
        "window_start_ns",
        "window_end_ns",
        "count",
        "linear_acceleration_x_count",
        "linear_acceleration_x_mean",
        "linear_acceleration_x_stddev",
        "orientation_covariance_0_count",
        "orientation_covariance_0_mean",
        "orientation_covariance_0_stddev",
    ]
    value = {"linear_acceleration": {"x": 2.0}, "orientation_covariance": [0.5] * 9}
    stage.process(sample(value, stamp_ns=T0), T0)
    record = stage.process(sample(value, stamp_ns=T0 + S), T0 + S)[0].value
    parsed = fastavro.parse_schema(derived)
    buf = io.BytesIO()
    fastavro.schemaless_writer(buf, parsed, record)
    buf.seek(0)
    assert fastavro.schemaless_reader(buf, parsed, parsed) == record
    # same fields and ops on the same type: same name; different ops: different name
    again = AggregateStage(
        ["linear_acceleration.x", "orientation_covariance[0]"], ["count", "mean", "stddev"], 2 * S
    )
    other = AggregateStage(["linear_acceleration.x", "orientation_covariance[0]"], ["count", "mean"], S)
    assert again.output_schema(schema(IMU_SCHEMA))["name"] == derived["name"]
    assert other.output_schema(schema(IMU_SCHEMA))["name"] != derived["name"]


@pytest.mark.parametrize(
    ("fields", "error", "message"),
    [
        (["linear_acceleration.w"], FieldPathError, "has no field 'w'"),
        (["header.frame_id"], StageConfigError, "'header.frame_id' of ros.sensor_msgs.msg.Imu is string"),
        (["orientation_covariance"], StageConfigError, "is array, not a number"),
        (["angular_velocity"], StageConfigError, "is record, not a number"),
    ],
)
def test_output_schema_refuses_non_numeric_fields(
    fields: list[str], error: type[Exception], message: str
) -> None:
    with pytest.raises(error, match=message):
        AggregateStage(fields, ["mean"], S).output_schema(schema(IMU_SCHEMA))


def test_bool_fields_are_refused() -> None:
    with pytest.raises(StageConfigError, match="is bool"):
        AggregateStage(["kidnap.is_kidnapped"], ["mean"], S).output_schema(schema(STATUS_SCHEMA))


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"fields": ["x"], "ops": ["mean"], "window_ns": 0}, "0 < hop <= window"),
        ({"fields": ["x"], "ops": ["mean"], "window_ns": S, "hop_ns": 2 * S}, "0 < hop <= window"),
        ({"fields": ["x"], "ops": ["median"], "window_ns": S}, "distinct ops"),
        ({"fields": ["x"], "ops": ["mean", "mean"], "window_ns": S}, "distinct ops"),
        ({"fields": [], "ops": ["mean"], "window_ns": S}, "distinct fields"),
        ({"fields": ["a_b.c", "a.b_c"], "ops": ["mean"], "window_ns": S}, "output field names collide"),
    ],
)
def test_bad_options(kwargs: dict[str, Any], message: str) -> None:
    with pytest.raises(StageConfigError, match=message):
        AggregateStage(**kwargs)
