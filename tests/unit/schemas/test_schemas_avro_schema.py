"""Avro schemas generated from ROS types: mapping table, naming, determinism, validity."""

from __future__ import annotations

import json
from typing import Any

import avro.schema
import fastavro
import pytest

from fleetlink.schemas.avro_schema import avro_fullname, avro_schema
from fleetlink.schemas.typehash import HUMBLE_HASH
from fleetlink.schemas.typestore import load_typestore, message_types, types_from_msg

TS = load_typestore("jazzy")
ALL_KINDS = """
bool a_bool
byte a_byte
char a_char
int8 a_int8
uint8 a_uint8
int16 a_int16
uint16 a_uint16
int32 a_int32
uint32 a_uint32
int64 a_int64
uint64 a_uint64
float32 a_float32
float64 a_float64
string a_string
string<=5 a_bounded_string
uint8[] a_uint8_seq
uint8[4] a_uint8_fixed
byte[] a_byte_seq
char[16] a_char_fixed
bool[] a_bool_seq
float64[9] a_float64_fixed
float32[<=3] a_float32_bounded
int32[] a_int32_seq
uint64[2] a_uint64_fixed
string[] a_string_seq
string<=4[<=2] a_bounded_strings
builtin_interfaces/Time a_time
builtin_interfaces/Time[] a_times
builtin_interfaces/Duration a_duration
int32 SOME_CONSTANT=7
string NAME="hello"
"""
TS.register(types_from_msg(ALL_KINDS, "t_msgs/msg/AllKinds"))


def _fields(schema: dict[str, Any]) -> dict[str, dict[str, Any]]:
    return {f["name"]: f for f in schema["fields"]}


@pytest.mark.parametrize(
    ("field", "avro_type", "ros_type"),
    [
        ("a_bool", "boolean", "bool"),
        ("a_byte", "int", "byte"),
        ("a_char", "int", "char"),
        ("a_int8", "int", "int8"),
        ("a_uint8", "int", "uint8"),
        ("a_int16", "int", "int16"),
        ("a_uint16", "int", "uint16"),
        ("a_int32", "int", "int32"),
        ("a_uint32", "long", "uint32"),
        ("a_int64", "long", "int64"),
        ("a_uint64", "long", "uint64"),
        ("a_float32", "float", "float32"),
        ("a_float64", "double", "float64"),
        ("a_string", "string", "string"),
        ("a_bounded_string", "string", "string<=5"),
        ("a_uint8_seq", "bytes", "uint8[]"),
        ("a_uint8_fixed", "bytes", "uint8[4]"),
        ("a_byte_seq", "bytes", "byte[]"),
        ("a_char_fixed", "bytes", "char[16]"),
        ("a_bool_seq", {"type": "array", "items": "boolean"}, "bool[]"),
        ("a_float64_fixed", {"type": "array", "items": "double"}, "float64[9]"),
        ("a_float32_bounded", {"type": "array", "items": "float"}, "float32[<=3]"),
        ("a_int32_seq", {"type": "array", "items": "int"}, "int32[]"),
        ("a_uint64_fixed", {"type": "array", "items": "long"}, "uint64[2]"),
        ("a_string_seq", {"type": "array", "items": "string"}, "string[]"),
        ("a_bounded_strings", {"type": "array", "items": "string"}, "string<=4[<=2]"),
        (
            "a_times",
            {"type": "array", "items": "ros.builtin_interfaces.msg.Time"},
            "builtin_interfaces/msg/Time[]",
        ),
        ("a_duration", None, "builtin_interfaces/msg/Duration"),
    ],
)
def test_type_mapping(field: str, avro_type: Any, ros_type: str) -> None:
    entry = _fields(avro_schema(TS, "t_msgs/msg/AllKinds", "jazzy"))[field]
    if avro_type is not None:
        assert entry["type"] == avro_type
    assert entry["ros_type"] == ros_type


def test_time_and_duration_are_records_like_ros() -> None:
    fields = _fields(avro_schema(TS, "t_msgs/msg/AllKinds", "jazzy"))
    time = fields["a_time"]["type"]
    assert (time["type"], time["name"], time["namespace"]) == ("record", "Time", "ros.builtin_interfaces.msg")
    assert [(f["name"], f["type"]) for f in time["fields"]] == [("sec", "int"), ("nanosec", "long")]
    duration = fields["a_duration"]["type"]
    assert duration["name"] == "Duration"
    assert [(f["name"], f["type"]) for f in duration["fields"]] == [("sec", "int"), ("nanosec", "long")]


def test_constants_are_documented() -> None:
    doc = avro_schema(TS, "t_msgs/msg/AllKinds", "jazzy")["doc"]
    assert "int32 SOME_CONSTANT=7" in doc
    assert "string NAME='hello'" in doc


def test_nested_records_defined_once_then_referenced() -> None:
    schema = avro_schema(TS, "nav_msgs/msg/Odometry", "jazzy")
    text = json.dumps(schema)
    assert text.count('"name": "Vector3"') == 1
    twist = _fields(_fields(schema)["twist"]["type"])["twist"]["type"]
    assert _fields(twist)["linear"]["type"]["name"] == "Vector3"
    assert _fields(twist)["angular"]["type"] == "ros.geometry_msgs.msg.Vector3"


@pytest.mark.parametrize(
    ("distro", "expected"),
    [
        ("jazzy", "RIHS01_7d9a00ff131080897a5ec7e26e315954b8eae3353c3f995c55faf71574000b5b"),
        ("humble", HUMBLE_HASH),
    ],
)
def test_top_level_properties(distro: str, expected: str) -> None:
    ts = load_typestore(distro)  # type: ignore[arg-type]
    schema = avro_schema(ts, "sensor_msgs/msg/Imu", distro)  # type: ignore[arg-type]
    assert schema["ros_type"] == "sensor_msgs/msg/Imu"
    assert schema["ros_type_hash"] == expected
    assert (schema["namespace"], schema["name"]) == ("ros.sensor_msgs.msg", "Imu")


def test_deterministic_across_stores() -> None:
    other = load_typestore("jazzy")
    for name in ("sensor_msgs/msg/Imu", "tf2_msgs/msg/TFMessage", "sensor_msgs/msg/PointCloud2"):
        assert json.dumps(avro_schema(TS, name, "jazzy")) == json.dumps(avro_schema(other, name, "jazzy"))


@pytest.mark.parametrize(
    ("typename", "fullname"),
    [
        ("sensor_msgs/msg/Imu", "ros.sensor_msgs.msg.Imu"),
        ("example_interfaces/srv/AddTwoInts_Request", "ros.example_interfaces.srv.AddTwoInts_Request"),
    ],
)
def test_fullname(typename: str, fullname: str) -> None:
    assert avro_fullname(typename) == fullname


@pytest.mark.parametrize("typename", [*message_types(load_typestore("jazzy")), "t_msgs/msg/AllKinds"])
def test_valid_for_both_avro_libraries(typename: str) -> None:
    schema = avro_schema(TS, typename, "jazzy")
    fastavro.parse_schema(schema)
    parsed = avro.schema.parse(json.dumps(schema))
    assert isinstance(parsed, avro.schema.RecordSchema)
    assert parsed.fullname == avro_fullname(typename)
