"""The filter stage: what it lets through, what it counts, how it checks a schema."""

from __future__ import annotations

import logging

import pytest

from fleetlink.edge.stages import ExpressionError, FilterStage, Sample
from tests.unit.edge.stages.messages import IMU_SCHEMA, STATUS_SCHEMA, sample, schema, status_value


@pytest.mark.parametrize(
    ("expr", "values", "passed", "dropped", "errors"),
    [
        ("level > 2", [{"level": 1}, {"level": 3}, {"level": 5}], 2, 1, 0),
        ("mode == 'dock'", [{"mode": "dock"}, {"mode": "undock"}], 1, 1, 0),
        ("level > 2", [{"level": "three"}, {"level": 3}], 1, 0, 1),
        ("missing > 2", [{}, {}], 0, 0, 2),
        ("ranges[5] > 0", [{}], 0, 0, 1),
        ("level / (level - 3) > 0", [{"level": 3}, {"level": 4}], 1, 0, 1),
        (
            "kidnap.is_kidnapped",
            [{"kidnap": {"is_kidnapped": True}}, {"kidnap": {"is_kidnapped": 1}}],
            1,
            0,
            1,
        ),
    ],
)
def test_counts(expr: str, values: list[dict[str, object]], passed: int, dropped: int, errors: int) -> None:
    stage = FilterStage(expr)
    out: list[Sample] = []
    for i, changes in enumerate(values):
        out += stage.process(sample(status_value(**changes), raw=b"cdr"), now_ns=i)
    assert stage.counters.as_dict() == {
        "received": len(values),
        "passed": passed,
        "dropped": dropped,
        "late": 0,
        "errors": errors,
        "emitted": passed,
        "nan": 0,
    }
    assert len(out) == passed
    assert all(s.raw == b"cdr" for s in out)  # untouched samples keep their CDR
    assert (stage.last_error is None) == (errors == 0)


def test_forwards_the_same_sample_object() -> None:
    stage = FilterStage("level == 3")
    item = sample(status_value())
    assert stage.process(item, 0)[0] is item
    assert stage.tick(10**12) == []


def test_first_evaluation_error_is_logged_then_only_counted(caplog: pytest.LogCaptureFixture) -> None:
    stage = FilterStage("level > 1")
    with caplog.at_level(logging.WARNING, logger="fleetlink.edge.stages.filter"):
        for _ in range(3):
            stage.process(sample({"level": "x"}), 0)
        stage.process(sample({}), 0)
    assert len(caplog.records) == 1
    assert "expr='level > 1'" in caplog.records[0].getMessage()
    assert stage.counters.errors == 4
    assert stage.last_error is not None
    assert stage.last_error.startswith("KeyError")


def test_bad_expression_is_refused_at_construction() -> None:
    with pytest.raises(ExpressionError) as info:
        FilterStage("level >")
    assert info.value.column == 8


def test_output_schema_is_the_input_schema() -> None:
    stage = FilterStage("linear_acceleration.x > 1")
    imu = schema(IMU_SCHEMA)
    assert stage.output_schema(imu) is imu


@pytest.mark.parametrize(
    ("expr", "type_schema", "column", "fragment"),
    [
        ("linear_acceleration.w > 1", IMU_SCHEMA, 1, "field path 'linear_acceleration.w'"),
        ("level > 1 && kidnap.kidnapped", STATUS_SCHEMA, 14, "has no field 'kidnapped'"),
        ("mode > 1", STATUS_SCHEMA, 6, "cannot compare string with number"),
    ],
)
def test_output_schema_checks_paths_and_kinds(
    expr: str, type_schema: dict[str, object], column: int, fragment: str
) -> None:
    with pytest.raises(ExpressionError) as info:
        FilterStage(expr).output_schema(schema(type_schema))
    assert info.value.column == column
    assert fragment in str(info.value)
