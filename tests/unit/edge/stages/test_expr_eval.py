"""Evaluating compiled expressions, and checking them against a message's Avro schema."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from fleetlink.edge.stages.avro import kind_of, resolve_path, root_node
from fleetlink.edge.stages.errors import EvaluationError, ExpressionError
from fleetlink.edge.stages.expr import check_predicate, compile_predicate, parse_expression
from fleetlink.edge.stages.paths import Steps
from tests.unit.edge.stages.messages import IMU_SCHEMA, STATUS_SCHEMA, sample, schema, status_value

FAILS = "fails"
SAMPLE_ERRORS = (EvaluationError, LookupError, TypeError, ValueError, ArithmeticError)


def evaluate(source: str, value: dict[str, Any], **meta: Any) -> bool:
    predicate = compile_predicate(parse_expression(source))
    return predicate(sample(value, **meta))


@pytest.mark.parametrize(
    ("source", "changes", "expected"),
    [
        # the brief's example
        ("kidnap.is_kidnapped == true || data.size() > 3", {}, True),
        ("kidnap.is_kidnapped == true || data.size() > 4", {}, False),
        ("kidnap.is_kidnapped || last_kidnap.is_kidnapped", {}, True),
        ("kidnap.is_kidnapped && missing > 1", {}, False),  # && short-circuits
        ("last_kidnap.is_kidnapped || missing > 1", {}, True),  # || short-circuits
        ("!kidnap.is_kidnapped", {}, True),
        # numbers: int/float mix, arithmetic, precedence
        ("level == 3", {}, True),
        ("level == 3.0", {}, True),
        ("level + 1 == 4 && level * 2 - 1 == 5", {}, True),
        ("level / 2 == 1.5", {}, True),
        ("level % 2 == 1", {}, True),
        ("-level < -2", {}, True),
        ("battery >= 0.5 && battery <= 0.5", {}, True),
        ("abs(battery - 1) == 0.5", {}, True),
        ("sqrt(level * level) == 3", {}, True),
        ("max(level, battery, 2) == 3 && min(level, battery) == 0.5", {}, True),
        (
            "level > 2 == true",
            {},
            FAILS,
        ),  # parses as level > (2 == true): chained is refused, see parse tests
        # strings and metadata
        ("mode == 'dock'", {}, True),
        ('mode != "dock"', {}, False),
        ("mode < 'e' && mode > 'c'", {}, True),
        ("mode + '/x' == 'dock/x'", {}, True),
        ("len(mode) == 4 && mode.size() == 4", {}, True),
        ("mode in ['undock', 'dock']", {}, True),
        ("level in [1, 2]", {}, False),
        ("level in [3.0]", {}, True),
        ("kidnap.is_kidnapped in [false]", {}, True),
        ("@robot == 'tb4_01' && @topic == '/tb4_01/x'", {}, True),
        ("@stamp_ns > 0", {}, False),
        # arrays, bytes, numpy
        ("ranges[1] == 0.5", {}, True),
        ("ranges[-1] == 2", {}, True),
        ("data[0] == 1 && data[-1] == 4", {}, True),
        ("names[1] == 'b'", {}, True),
        ("len(ranges) == 3 && size(names) == 2", {}, True),
        ("any(ranges < 0.6)", {}, True),
        ("any(ranges < 0.4)", {}, False),
        ("all(ranges > 0.4)", {}, True),
        ("all(0.6 < ranges)", {}, False),
        ("any(ranges == 2)", {}, True),
        ("any(names == 'b')", {}, True),
        ("all(names != 'c')", {}, True),
        ("any(data > 3)", {}, True),
        ("any(ranges < 1)", {"ranges": []}, False),
        ("all(ranges < 1)", {"ranges": []}, True),
        ("any(ranges < 1)", {"ranges": [2.0, 0.5]}, True),
        ("min(ranges) == 0.5 && max(ranges) == 2", {}, True),
        ("max(ranges) == 2", {"ranges": [1, 2, 0]}, True),
        ("min(data) == 1", {}, True),
        # NaN follows IEEE: comparisons false, != true
        ("battery < 1", {"battery": math.nan}, False),
        ("battery != battery", {"battery": math.nan}, True),
        ("isnan(battery) && !isfinite(battery)", {"battery": math.nan}, True),
        ("isfinite(battery)", {"battery": math.inf}, False),
        ("any(ranges > 1)", {"ranges": np.array([math.nan, 0.5])}, False),
        # numpy scalars in the value
        ("level == 3 && battery > 0.4", {"level": np.int64(3), "battery": np.float32(0.5)}, True),
        # evaluation errors: never a wrong answer
        ("missing > 1", {}, FAILS),
        ("kidnap.missing", {}, FAILS),
        ("ranges[7] > 0", {}, FAILS),
        ("mode > 1", {}, FAILS),
        ("level == 'x'", {}, FAILS),
        ("level == true", {}, FAILS),
        ("mode", {}, FAILS),  # not a bool
        ("level && true", {}, FAILS),
        ("!mode", {}, FAILS),
        ("level / 0 > 1", {}, FAILS),
        ("level % 0 > 1", {}, FAILS),
        ("sqrt(-level) > 0", {}, FAILS),
        ("abs(mode) > 0", {}, FAILS),
        ("len(level) > 0", {}, FAILS),
        ("min(ranges) > 0", {"ranges": []}, FAILS),
        ("max(names) > 0", {}, FAILS),
        ("min(level) > 0", {}, FAILS),
        ("any(level > 0)", {}, FAILS),
        ("any(ranges == ranges)", {}, FAILS),
        ("any(names > 1)", {}, FAILS),
        ("ranges == 1", {}, FAILS),
        ("ranges < 1", {}, FAILS),
        ("mode in ['a'] && kidnap in [1]", {"mode": "a"}, FAILS),
        ("-mode < 0", {}, FAILS),
        ("mode * 2 == 'x'", {}, FAILS),
        ("header.stamp == 5", {}, FAILS),
        ("maybe > 1", {}, FAILS),  # null
    ],
)
def test_evaluate(source: str, changes: dict[str, Any], expected: bool | str) -> None:
    value = status_value(**changes)
    if expected == FAILS:
        try:
            parse_expression(source)
        except ExpressionError:
            return  # refused before it could ever run: also fine
        with pytest.raises(SAMPLE_ERRORS):
            evaluate(source, value)
        return
    result = evaluate(source, value)
    assert result is expected


def field_kinds(source_schema: dict[str, Any]) -> Any:
    index, root = root_node(schema(source_schema))

    def kind(steps: Steps) -> str:
        return kind_of(resolve_path(index, root, steps))

    return kind


@pytest.mark.parametrize(
    ("source", "type_schema", "column", "reason"),
    [
        ("linear_acceleration.x > 1 && angular_velocity.z < 0", IMU_SCHEMA, None, None),
        ("any(orientation_covariance > 0) && header.frame_id == 'imu_link'", IMU_SCHEMA, None, None),
        ("kidnap.is_kidnapped == true || data.size() > 3", STATUS_SCHEMA, None, None),
        ("data[0] == 1 && any(data > 3) && names[0] == 'a' && maybe > 1", STATUS_SCHEMA, None, None),
        ("linear_acceleration.q > 1", IMU_SCHEMA, 1, "has no field 'q' (it has: x, y, z)"),
        ("1 < linear_accel.x", IMU_SCHEMA, 5, "record 'ros.sensor_msgs.msg.Imu' has no field 'linear_accel'"),
        ("header.frame_id > 3", IMU_SCHEMA, 17, "cannot compare string with number"),
        ("header.stamp == 1", IMU_SCHEMA, 1, "'==' needs bool or bytes or number or string, got record"),
        ("orientation_covariance > 1", IMU_SCHEMA, 1, "'>' needs number or string, got array"),
        ("header.frame_id", IMU_SCHEMA, 1, "a filter must be a condition (true/false), this is a string"),
        ("kidnap.is_kidnapped + 1 > 0", STATUS_SCHEMA, 1, "'+' needs number, got bool"),
        ("len(level) > 0", STATUS_SCHEMA, 1, "len() needs array or bytes or map or string, got number"),
        ("min(mode) > 0", STATUS_SCHEMA, 1, "min() of one argument needs array or bytes, got string"),
        ("any(level > 1)", STATUS_SCHEMA, 5, "any() needs an array on one side"),
        ("any(ranges > ranges)", STATUS_SCHEMA, 5, "any() needs an array on one side only"),
        ("any(names > 1)", STATUS_SCHEMA, 11, "cannot compare string with number"),
        ("all(ranges != 'a')", STATUS_SCHEMA, 12, "cannot compare number with string"),
        ("level[0] > 1", STATUS_SCHEMA, 1, 'level is "int", not an array'),
    ],
)
def test_check_against_schema(
    source: str, type_schema: dict[str, Any], column: int | None, reason: str | None
) -> None:
    node = parse_expression(source)
    if column is None:
        check_predicate(node, source, field_kinds(type_schema))
        return
    with pytest.raises(ExpressionError) as info:
        check_predicate(node, source, field_kinds(type_schema))
    assert info.value.column == column, str(info.value)
    assert reason is not None
    assert reason in info.value.reason
