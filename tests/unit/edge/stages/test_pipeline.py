"""Stages composed into a pipeline: order, tick cascade, schema composition, names, counters."""

from __future__ import annotations

from typing import Any

import pytest
from pydantic import TypeAdapter

from fleetlink.edge.stages import (
    AggregateStage,
    ExpressionError,
    FieldPathError,
    FilterStage,
    OnChangeStage,
    Pipeline,
    Sample,
    Stage,
    StageConfigError,
    StageSpec,
    ThrottleStage,
    build_pipeline,
    build_stage,
)
from tests.unit.edge.stages.messages import IMU_SCHEMA, imu_value, sample, schema

MS = 1_000_000
S = 1_000_000_000
T0 = 1_700_000_000 * S


def specs(*items: dict[str, Any]) -> list[StageSpec]:
    return TypeAdapter(list[StageSpec]).validate_python(list(items))


@pytest.mark.parametrize(
    ("spec", "kind"),
    [
        ({"type": "filter", "expr": "x > 1"}, FilterStage),
        ({"type": "throttle", "hz": 5}, ThrottleStage),
        ({"type": "on_change", "fields": ["x"], "heartbeat": "1s"}, OnChangeStage),
        ({"type": "aggregate", "window": "1s", "fields": ["x"], "ops": ["mean"]}, AggregateStage),
    ],
)
def test_build_stage(spec: dict[str, Any], kind: type) -> None:
    stage = build_stage(specs(spec)[0])
    assert isinstance(stage, kind)
    assert isinstance(stage, Stage)
    assert stage.name == spec["type"]


def test_stages_run_in_order_and_count() -> None:
    pipeline = build_pipeline(
        specs(
            {"type": "filter", "expr": "linear_acceleration.x > 0"},
            {"type": "throttle", "hz": 10, "keep": "first"},
            {"type": "project", "fields": ["linear_acceleration.x"], "flatten": True},
        )
    )
    out: list[Sample] = []
    for i in range(100):  # 1 kHz for 100 ms, every other sample positive
        ax = 1.0 if i % 2 else -1.0
        out += pipeline.process(sample(imu_value(ax=ax), stamp_ns=i), T0 + i * MS)
    assert [s.value for s in out] == [{"linear_acceleration_x": 1.0}]
    assert pipeline.stage_counters() == {
        "filter": {
            "received": 100,
            "passed": 50,
            "dropped": 50,
            "late": 0,
            "errors": 0,
            "emitted": 50,
            "nan": 0,
        },
        "throttle": {
            "received": 50,
            "passed": 1,
            "dropped": 49,
            "late": 0,
            "errors": 0,
            "emitted": 1,
            "nan": 0,
        },
        "project": {"received": 1, "passed": 1, "dropped": 0, "late": 0, "errors": 0, "emitted": 1, "nan": 0},
    }
    assert (pipeline.counters.received, pipeline.counters.emitted) == (100, 1)


def test_tick_output_flows_through_the_later_stages() -> None:
    pipeline = build_pipeline(
        specs(
            {"type": "throttle", "hz": 1, "keep": "latest"},
            {"type": "filter", "expr": "linear_acceleration.x > 0"},
            {
                "type": "aggregate",
                "window": "1s",
                "fields": ["linear_acceleration.x"],
                "ops": ["count", "max"],
                "idle_timeout": "5s",
            },
        )
    )
    assert pipeline.process(sample(imu_value(ax=2.0), stamp_ns=T0), T0) == []
    # the throttle lets the held sample go on this tick; it passes the filter and opens a window
    assert pipeline.tick(T0 + S) == []
    assert pipeline.stage_counters()["aggregate"]["passed"] == 1
    # the aggregate's idle timeout (processing time since that sample) flushes the window
    assert pipeline.tick(T0 + 5 * S) == []
    out = pipeline.tick(T0 + 6 * S)
    assert [(s.value["count"], s.value["linear_acceleration_x_max"]) for s in out] == [(1, 2.0)]
    assert pipeline.counters.emitted == 1


def test_empty_pipeline_is_the_identity() -> None:
    pipeline = build_pipeline([])
    item = sample({"x": 1})
    assert pipeline.process(item, 0) == [item]
    assert pipeline.tick(0) == []
    imu = schema(IMU_SCHEMA)
    assert pipeline.output_schema(imu) is imu


def test_output_schema_composes() -> None:
    pipeline = build_pipeline(
        specs(
            {"type": "project", "fields": ["linear_acceleration.x", "angular_velocity.z"], "flatten": True},
            {"type": "filter", "expr": "angular_velocity_z > 0.1"},
            {"type": "aggregate", "window": "1s", "fields": ["linear_acceleration_x"], "ops": ["mean"]},
        )
    )
    derived = pipeline.output_schema(schema(IMU_SCHEMA))
    assert derived["namespace"] == "fleetlink.agg"
    assert derived["name"].startswith("Imu_proj_")  # named after the projected record it aggregates
    assert [f["name"] for f in derived["fields"]][-1] == "linear_acceleration_x_mean"


@pytest.mark.parametrize(
    ("items", "error", "fragment"),
    [
        (
            (
                {"type": "filter", "expr": "linear_acceleration.x > 0"},
                {"type": "project", "fields": ["linear_acceleration.x"], "flatten": True},
                {"type": "filter", "expr": "linear_acceleration.x > 0"},
            ),
            ExpressionError,
            "stage 2 (filter_2): column 1: field path 'linear_acceleration.x'",
        ),
        (
            ({"type": "throttle", "hz": 1}, {"type": "on_change", "fields": ["orientation.v"]}),
            FieldPathError,
            "stage 1 (on_change): field path 'orientation.v'",
        ),
        (
            ({"type": "aggregate", "window": "1s", "fields": ["header.frame_id"], "ops": ["max"]},),
            StageConfigError,
            "stage 0 (aggregate): aggregate: field 'header.frame_id'",
        ),
    ],
)
def test_schema_errors_name_the_stage_and_keep_their_class(
    items: tuple[dict[str, Any], ...], error: type[Exception], fragment: str
) -> None:
    with pytest.raises(error) as info:
        build_pipeline(specs(*items)).output_schema(schema(IMU_SCHEMA))
    assert fragment in str(info.value)
    if isinstance(info.value, FieldPathError):
        assert info.value.path == "orientation.v"


def test_names_are_unique() -> None:
    pipeline = build_pipeline(
        specs(
            {"type": "filter", "expr": "x > 0"},
            {"type": "filter", "expr": "x < 9", "name": "upper"},
            {"type": "filter", "expr": "x != 5"},
            {"type": "filter", "expr": "x != 6", "name": "filter_2"},
        )
    )
    assert [s.name for s in pipeline.stages] == ["filter", "upper", "filter_3", "filter_2"]
    with pytest.raises(StageConfigError, match="stage names must be unique"):
        build_pipeline(
            specs(
                {"type": "filter", "expr": "x > 0", "name": "f"}, {"type": "throttle", "hz": 1, "name": "f"}
            )
        )


def test_a_pipeline_is_a_stage() -> None:
    inner = Pipeline([FilterStage("x > 0")], name="inner")
    outer = Pipeline([inner, ThrottleStage(1, "first")])
    assert isinstance(inner, Stage)
    assert outer.process(sample({"x": 1}), 0) != []
    assert outer.process(sample({"x": 2}), 1) == []
    assert outer.stage_counters()["inner"]["received"] == 2
    assert outer.stage_counters()["inner"]["emitted"] == 2
    assert outer.process(sample({"x": -1}), 2) == []
    assert outer.process(sample({}), 3) == []
    totals = outer.totals()
    assert (totals.received, totals.emitted, totals.passed) == (4, 1, 1)
    assert inner.totals().as_dict() == {
        "received": 4,
        "passed": 2,
        "dropped": 1,
        "late": 0,
        "errors": 1,
        "emitted": 2,
        "nan": 0,
    }
    assert totals.dropped == 1  # the throttle's; a nested pipeline's own counters hold received/emitted only
