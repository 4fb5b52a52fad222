"""The project stage: values, derived schemas (nested and flat), names, errors."""

from __future__ import annotations

import io
from collections.abc import Mapping
from typing import Any

import fastavro
import pytest

from fleetlink.edge.stages import FieldPathError, ProjectStage, StageConfigError
from tests.unit.edge.stages.messages import IMU_SCHEMA, ODOMETRY_SCHEMA, imu_value, sample, schema


def odom_value() -> dict[str, Any]:
    vec = {"x": 0.0, "y": 0.0, "z": 0.0}
    return {
        "header": {"stamp": {"sec": 10, "nanosec": 5}, "frame_id": "odom"},
        "child_frame_id": "base_link",
        "pose": {
            "pose": {
                "position": {"x": 1.0, "y": 2.0, "z": 0.0},
                "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
            },
            "covariance": [0.0] * 36,
        },
        "twist": {
            "twist": {"linear": {**vec, "x": 0.25}, "angular": {**vec, "z": -0.5}},
            "covariance": [0.0] * 36,
        },
    }


def roundtrip(out_schema: dict[str, Any], value: Mapping[str, Any]) -> Any:
    """Encode with the derived schema and decode again: the value must fit the schema."""
    parsed = fastavro.parse_schema(out_schema)
    buf = io.BytesIO()
    fastavro.schemaless_writer(buf, parsed, value)
    buf.seek(0)
    return fastavro.schemaless_reader(buf, parsed, parsed)


def field_types(record: dict[str, Any]) -> dict[str, Any]:
    return {f["name"]: f["type"] for f in record["fields"]}


def test_nested_keeps_structure() -> None:
    stage = ProjectStage(["header.stamp", "twist.twist.linear.x", "twist.twist.angular.z"])
    out = stage.process(sample(odom_value(), raw=b"cdr", stamp_ns=7), 0)
    assert len(out) == 1
    assert out[0].raw is None  # the value changed: no fast path
    assert out[0].stamp_ns == 7
    expected = {
        "header": {"stamp": {"sec": 10, "nanosec": 5}},
        "twist": {"twist": {"linear": {"x": 0.25}, "angular": {"z": -0.5}}},
    }
    assert out[0].value == expected

    derived = stage.output_schema(schema(ODOMETRY_SCHEMA))
    name = derived["name"]
    assert name.startswith("ros.nav_msgs.msg.Odometry_proj_")
    assert list(field_types(derived)) == ["header", "twist"]
    header = field_types(derived)["header"]
    assert header["name"] == f"{name}_header"
    stamp = field_types(header)["stamp"]
    assert stamp["name"] == "ros.builtin_interfaces.msg.Time"  # a whole record keeps its type
    linear = field_types(field_types(field_types(derived)["twist"])["twist"])["linear"]
    assert linear == {
        "type": "record",
        "name": f"{name}_twist_twist_linear",
        "fields": [{"name": "x", "type": "double", "ros_type": "float64"}],
    }
    assert roundtrip(derived, out[0].value) == expected


def test_flat_names_paths_with_underscores_and_allows_elements() -> None:
    stage = ProjectStage(
        ["header.stamp", "linear_acceleration.x", "orientation_covariance[0]", "angular_velocity"],
        flatten=True,
    )
    value = imu_value(1_500_000_000, ax=0.5)
    out = stage.process(sample(value), 0)[0].value
    assert out == {
        "header_stamp": {"sec": 1, "nanosec": 500_000_000},
        "linear_acceleration_x": 0.5,
        "orientation_covariance_0": 0.0,
        "angular_velocity": {"x": 0.0, "y": 0.0, "z": 0.0},
    }
    derived = stage.output_schema(schema(IMU_SCHEMA))
    types = field_types(derived)
    assert types["linear_acceleration_x"] == "double"
    assert types["orientation_covariance_0"] == "double"
    assert types["angular_velocity"]["name"] == "ros.geometry_msgs.msg.Vector3"
    assert types["header_stamp"]["name"] == "ros.builtin_interfaces.msg.Time"
    ros_types = {f["name"]: f.get("ros_type") for f in derived["fields"]}
    assert ros_types["linear_acceleration_x"] == "float64"  # field attributes travel along
    assert roundtrip(derived, out) == out


def test_a_type_used_twice_is_defined_once() -> None:
    stage = ProjectStage(["angular_velocity", "linear_acceleration"])
    derived = stage.output_schema(schema(IMU_SCHEMA))
    types = field_types(derived)
    assert types["angular_velocity"]["name"] == "ros.geometry_msgs.msg.Vector3"
    assert types["linear_acceleration"] == "ros.geometry_msgs.msg.Vector3"
    value = stage.process(sample(imu_value(ax=2.0)), 0)[0].value
    assert roundtrip(derived, value) == value


@pytest.mark.parametrize(
    ("fields", "flatten", "same"),
    [
        (["linear_acceleration.x"], False, True),
        (["linear_acceleration.x"], True, False),
        (["linear_acceleration.y"], False, False),
        (["linear_acceleration.x", "angular_velocity.z"], False, False),
    ],
)
def test_derived_name_is_deterministic(fields: list[str], flatten: bool, same: bool) -> None:
    base = ProjectStage(["linear_acceleration.x"]).output_schema(schema(IMU_SCHEMA))
    other = ProjectStage(fields, flatten=flatten).output_schema(schema(IMU_SCHEMA))
    assert (base["name"] == other["name"]) is same
    assert ProjectStage(fields, flatten=flatten).output_schema(schema(IMU_SCHEMA)) == other


@pytest.mark.parametrize(
    ("fields", "flatten", "message"),
    [
        (["ranges[0]"], False, "indexes an array; use flatten: true"),
        (["twist.twist", "twist.twist.linear.x"], False, "paths overlap at 'twist.twist'"),
        (["twist.twist.linear.x", "twist.twist"], False, "paths overlap at 'twist.twist'"),
        (["a.b", "a.b"], False, "listed twice"),
        (["a_b.c", "a.b_c"], True, "flattened field names collide"),
        ([], False, "at least one field"),
        (["a..b"], False, "invalid field path"),
    ],
)
def test_bad_field_lists(fields: list[str], flatten: bool, message: str) -> None:
    with pytest.raises(StageConfigError, match=message):
        ProjectStage(fields, flatten=flatten)


@pytest.mark.parametrize("flatten", [False, True])
def test_paths_are_checked_against_the_schema(flatten: bool) -> None:
    with pytest.raises(FieldPathError) as info:
        ProjectStage(["header.stamp", "twist.twist.linear.q"], flatten=flatten).output_schema(
            schema(ODOMETRY_SCHEMA)
        )
    assert info.value.path == "twist.twist.linear.q"
    assert "has no field 'q'" in str(info.value)


def test_a_value_without_the_field_is_counted_not_raised() -> None:
    stage = ProjectStage(["twist.twist.linear.x"])
    assert stage.process(sample({"twist": {}}), 0) == []
    assert stage.process(sample({"twist": 5}), 0) == []
    assert stage.process(sample(odom_value()), 0) != []
    assert stage.counters.as_dict() == {
        "received": 3,
        "passed": 1,
        "dropped": 0,
        "late": 0,
        "errors": 2,
        "emitted": 1,
        "nan": 0,
    }
    assert stage.tick(10**18) == []
