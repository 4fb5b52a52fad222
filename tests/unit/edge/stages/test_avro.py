"""Resolving field paths in Avro schemas, self-contained copies, derived names."""

from __future__ import annotations

from typing import Any

import fastavro
import pytest

from fleetlink.edge.stages.avro import copy_self_contained, kind_of, resolve_path, root_node, short_hash
from fleetlink.edge.stages.errors import FieldPathError, StageConfigError
from fleetlink.edge.stages.paths import parse_path
from tests.unit.edge.stages.messages import IMU_SCHEMA, ODOMETRY_SCHEMA, STATUS_SCHEMA, schema


@pytest.mark.parametrize(
    ("source", "path", "kind"),
    [
        (IMU_SCHEMA, "linear_acceleration.x", "number"),  # through a by-name reference
        (IMU_SCHEMA, "angular_velocity", "record"),
        (IMU_SCHEMA, "header.stamp.nanosec", "number"),
        (IMU_SCHEMA, "header.frame_id", "string"),
        (IMU_SCHEMA, "orientation_covariance", "array"),
        (IMU_SCHEMA, "orientation_covariance[4]", "number"),
        (ODOMETRY_SCHEMA, "twist.twist.angular.z", "number"),
        (ODOMETRY_SCHEMA, "pose.pose.orientation.w", "number"),
        (STATUS_SCHEMA, "last_kidnap.is_kidnapped", "bool"),  # relative name in the namespace
        (STATUS_SCHEMA, "data", "bytes"),
        (STATUS_SCHEMA, "data[0]", "number"),
        (STATUS_SCHEMA, "names[1]", "string"),
        (STATUS_SCHEMA, "maybe", "number"),  # nullable: the non-null branch
    ],
)
def test_resolve(source: dict[str, object], path: str, kind: str) -> None:
    index, root = root_node(schema(source))
    assert kind_of(resolve_path(index, root, parse_path(path))) == kind


@pytest.mark.parametrize(
    ("source", "path", "message"),
    [
        (
            IMU_SCHEMA,
            "linear_acceleration.q",
            "'linear_acceleration.q': record 'ros.geometry_msgs.msg.Vector3' has no field 'q' "
            "(it has: x, y, z)",
        ),
        (IMU_SCHEMA, "header.stamp.sec.x", "header.stamp.sec is \"int\", which has no field 'x'"),
        (IMU_SCHEMA, "nope", "record 'ros.sensor_msgs.msg.Imu' has no field 'nope'"),
        (IMU_SCHEMA, "header[0]", "header is record 'ros.std_msgs.msg.Header', not an array"),
        (
            ODOMETRY_SCHEMA,
            "twist.linear.x",
            "record 'ros.geometry_msgs.msg.TwistWithCovariance' has no field",
        ),
        (STATUS_SCHEMA, "ranges.x", "ranges is array, which has no field 'x'"),
    ],
)
def test_resolve_errors_name_path_and_type(source: dict[str, object], path: str, message: str) -> None:
    index, root = root_node(schema(source))
    with pytest.raises(FieldPathError) as info:
        resolve_path(index, root, parse_path(path))
    assert message in str(info.value)
    assert info.value.path == path
    assert info.value.type_name == f"{source['namespace']}.{source['name']}"


def test_non_record_input_is_refused() -> None:
    with pytest.raises(StageConfigError, match="record schema"):
        root_node({"type": "array", "items": "double"})


@pytest.mark.parametrize(
    "bad",
    [
        {"type": "record", "fields": []},  # no name
        {"type": "record", "name": "R", "fields": [{"name": "x"}]},
        {"type": "record", "name": "R", "fields": [{"name": "x", "type": {"type": "record", "fields": []}}]},
        {"type": "record", "name": "R", "fields": 3},
        {"type": "record", "name": "R"},
    ],
)
def test_malformed_input_schema_is_a_config_error(bad: dict[str, Any]) -> None:
    with pytest.raises(StageConfigError, match="not a valid Avro schema"):
        root_node(bad)


def test_unknown_reference_is_an_error() -> None:
    bad = {"type": "record", "name": "R", "fields": [{"name": "x", "type": "ros.Missing"}]}
    index, root = root_node(bad)
    with pytest.raises(StageConfigError, match=r"unknown type 'ros\.Missing'"):
        resolve_path(index, root, ("x",))


@pytest.mark.parametrize(
    ("source", "paths"),
    [
        (IMU_SCHEMA, ["linear_acceleration", "angular_velocity"]),  # the reference is defined on first use
        (IMU_SCHEMA, ["header"]),
        (ODOMETRY_SCHEMA, ["twist.twist", "pose.pose.orientation"]),
        (STATUS_SCHEMA, ["last_kidnap", "kidnap"]),
    ],
)
def test_copies_are_self_contained_and_define_each_type_once(
    source: dict[str, object], paths: list[str]
) -> None:
    index, root = root_node(schema(source))
    defined: set[str] = set()
    fields: list[dict[str, Any]] = [
        {
            "name": f"f{i}",
            "type": copy_self_contained(resolve_path(index, root, parse_path(p)), index, defined),
        }
        for i, p in enumerate(paths)
    ]
    out = {"type": "record", "name": "Out", "namespace": "x.y", "fields": fields}
    parsed = fastavro.parse_schema(out)  # raises if a type is missing or defined twice
    assert isinstance(parsed, dict)
    assert parsed["name"] == "x.y.Out"
    assert len(defined) >= 1
    first = fields[0]["type"]
    assert isinstance(first, dict)
    assert "." in first["name"]  # full names, so the copy does not depend on its new namespace


def test_short_hash_is_stable_and_sensitive() -> None:
    assert short_hash(["a", [1, 2]]) == short_hash(["a", [1, 2]])
    assert short_hash(["a", [1, 2]]) != short_hash(["a", [2, 1]])
    assert len(short_hash(["a"])) == 8
