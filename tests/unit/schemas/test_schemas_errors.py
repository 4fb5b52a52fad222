"""Bad input gets a precise error (type name + offset), never IndexError or struct.error."""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fleetlink.schemas.codec import get_codec
from fleetlink.schemas.errors import DecodeError, EncodeError, SchemaError, UnknownTypeError, ValueRangeError
from fleetlink.schemas.typestore import load_typestore, message_types
from fleetlink.schemas.wire import zz
from tests.unit.schemas.ros_values import same

TS = load_typestore("jazzy")


def cdr(typename: str, *args: Any) -> bytes:
    return bytes(TS.serialize_cdr(TS.types[typename](*args), typename))


def imu() -> bytes:
    t = TS.types
    header = t["std_msgs/msg/Header"](t["builtin_interfaces/msg/Time"](1, 2), "imu_link")
    quat = t["geometry_msgs/msg/Quaternion"](0.0, 0.0, 0.0, 1.0)
    vec = t["geometry_msgs/msg/Vector3"](1.0, 2.0, 3.0)
    cov = np.arange(9, dtype=np.float64)
    return cdr("sensor_msgs/msg/Imu", header, quat, cov, vec, cov, vec, cov)


PARAM = cdr(
    "rcl_interfaces/msg/ParameterValue",
    *(0, False, 0, 0.0, ""),
    *(np.zeros(0, np.int8), np.array([True, True]), np.zeros(0, np.int64), np.zeros(0), []),
)
assert PARAM[44:46] == b"\x01\x01"
STRING_HELLO = cdr("std_msgs/msg/String", "héllo")  # 00010000 07000000 68 c3a9 6c6c6f 00


def _replace(data: bytes, offset: int, new: bytes) -> bytes:
    return data[:offset] + new + data[offset + len(new) :]


CDR_CASES = [
    # (name, type, payload, offset, words in the reason)
    ("empty", "std_msgs/msg/String", b"", 0, "header"),
    ("short header", "std_msgs/msg/String", b"\x00\x01", 2, "header"),
    ("wrong first byte", "std_msgs/msg/String", _replace(STRING_HELLO, 0, b"\x01"), 0, "encapsulation"),
    ("PL_CDR", "std_msgs/msg/String", _replace(STRING_HELLO, 1, b"\x03"), 1, "encapsulation"),
    ("XCDR2", "std_msgs/msg/String", _replace(STRING_HELLO, 1, b"\x07"), 1, "encapsulation"),
    ("no body", "std_msgs/msg/String", b"\x00\x01\x00\x00", 4, "truncated: data"),
    ("length past end", "std_msgs/msg/String", _replace(STRING_HELLO, 4, b"\xff\x00\x00\x00"), 4, "length"),
    ("length zero", "std_msgs/msg/String", _replace(STRING_HELLO, 4, b"\x00\x00\x00\x00"), 4, "length"),
    ("no NUL", "std_msgs/msg/String", STRING_HELLO[:-1] + b"x", 14, "NUL"),
    ("invalid UTF-8", "std_msgs/msg/String", _replace(STRING_HELLO, 9, b"\xff"), 9, "UTF-8"),
    ("trailing bytes", "std_msgs/msg/String", STRING_HELLO + bytes(8), 15, "after the end"),
    ("bad bool", "std_msgs/msg/Bool", b"\x00\x01\x00\x00\x02", 4, "bool"),
    ("truncated double", "geometry_msgs/msg/Twist", b"\x00\x01\x00\x00" + bytes(36), 36, "angular.y"),
    (
        "sequence count too large",
        "std_msgs/msg/Float64MultiArray",
        b"\x00\x01\x00\x00" + struct.pack("<III", 0, 0, 0x0FFFFFFF),
        12,
        "sequence",
    ),
    ("bad bool in sequence", "rcl_interfaces/msg/ParameterValue", _replace(PARAM, 45, b"\x07"), 45, "0x07"),
]


@pytest.mark.parametrize(
    ("typename", "payload", "offset", "words"), [c[1:] for c in CDR_CASES], ids=[c[0] for c in CDR_CASES]
)
def test_bad_cdr(typename: str, payload: bytes, offset: int, words: str) -> None:
    with pytest.raises(DecodeError) as info:
        get_codec(TS, typename, "jazzy").cdr_to_avro(payload)
    err = info.value
    assert err.typename == typename
    assert err.offset == offset
    assert words in err.reason
    assert err.data == payload
    assert typename in str(err)
    # decode() walks the same bytes and fails the same way
    with pytest.raises(DecodeError) as again:
        get_codec(TS, typename, "jazzy").decode(payload)
    assert (again.value.offset, again.value.reason) == (err.offset, err.reason)


def test_up_to_three_alignment_bytes_are_accepted() -> None:
    codec = get_codec(TS, "std_msgs/msg/String", "jazzy")
    assert codec.cdr_to_avro(STRING_HELLO + b"\x00") == codec.cdr_to_avro(STRING_HELLO)


@pytest.mark.parametrize("cut", range(len(imu())))
def test_every_truncation_of_imu(cut: int) -> None:
    data = imu()[:cut]
    with pytest.raises(DecodeError) as info:
        get_codec(TS, "sensor_msgs/msg/Imu", "jazzy").cdr_to_avro(data)
    assert 0 <= info.value.offset <= max(cut, 4)


@pytest.mark.parametrize(
    ("typename", "payload", "field", "offset"),
    [
        ("std_msgs/msg/UInt64", b"\x00\x01\x00\x00" + struct.pack("<Q", 2**64 - 1), "data", 4),
        ("std_msgs/msg/UInt64", b"\x00\x01\x00\x00" + struct.pack("<Q", 2**63), "data", 4),
        (
            "std_msgs/msg/UInt64MultiArray",
            cdr(
                "std_msgs/msg/UInt64MultiArray",
                TS.types["std_msgs/msg/MultiArrayLayout"]([], 0),
                np.array([1, 2**63 + 5], dtype=np.uint64),
            ),
            "data[1]",
            28,
        ),
    ],
)
def test_uint64_above_long_range(typename: str, payload: bytes, field: str, offset: int) -> None:
    with pytest.raises(ValueRangeError) as info:
        get_codec(TS, typename, "jazzy").cdr_to_avro(payload)
    with pytest.raises(ValueRangeError) as again:
        get_codec(TS, typename, "jazzy").decode(payload)
    assert (again.value.field, again.value.offset) == (field, offset)
    assert info.value.field == field
    assert info.value.offset == offset
    assert info.value.typename == typename


@pytest.mark.parametrize(
    ("typename", "value"),
    [
        ("std_msgs/msg/UInt64", 2**63 - 1),
        ("std_msgs/msg/UInt32", 2**32 - 1),
        ("std_msgs/msg/Int64", -(2**63)),
    ],
)
def test_extremes_that_fit(typename: str, value: int) -> None:
    data = cdr(typename, value)
    codec = get_codec(TS, typename, "jazzy")
    assert codec.decode(data) == {"data": value}
    assert codec.avro_to_cdr(codec.cdr_to_avro(data)) == data


def test_nan_is_kept() -> None:
    data = b"\x00\x01\x00\x00" + struct.pack("<d", float("nan"))
    codec = get_codec(TS, "std_msgs/msg/Float64", "jazzy")
    assert codec.avro_to_cdr(codec.cdr_to_avro(data)) == data


AVRO_CASES = [
    # (name, type, avro body, exception, offset, words)
    ("empty", "std_msgs/msg/Int32", b"", DecodeError, 0, "truncated varint"),
    ("trailing", "std_msgs/msg/Int32", zz(5) + b"\x00", DecodeError, 1, "continues after"),
    ("int8 too big", "std_msgs/msg/Int8", zz(128), ValueRangeError, 0, "outside [-128, 127]"),
    ("uint8 negative", "std_msgs/msg/UInt8", zz(-1), ValueRangeError, 0, "outside [0, 255]"),
    ("uint64 negative", "std_msgs/msg/UInt64", zz(-5), ValueRangeError, 0, "outside"),
    ("int32 from a long", "std_msgs/msg/Int32", zz(2**40), ValueRangeError, 0, "outside"),
    ("bad bool", "std_msgs/msg/Bool", b"\x02", DecodeError, 0, "boolean"),
    ("string past end", "std_msgs/msg/String", zz(10) + b"abc", DecodeError, 0, "does not fit"),
    ("string bad UTF-8", "std_msgs/msg/String", zz(2) + b"a\xff", DecodeError, 2, "UTF-8"),
    ("varint too long", "std_msgs/msg/Int64", b"\xff" * 11, DecodeError, 0, "longer than 10 bytes"),
    ("double truncated", "std_msgs/msg/Float64", b"\x00" * 5, DecodeError, 0, "truncated"),
    (
        "fixed array length",
        "std_msgs/msg/ColorRGBA",
        b"\x00" * 12,
        DecodeError,
        12,
        "truncated",
    ),
]


@pytest.mark.parametrize(
    ("typename", "body", "exc", "offset", "words"),
    [c[1:] for c in AVRO_CASES],
    ids=[c[0] for c in AVRO_CASES],
)
def test_bad_avro(typename: str, body: bytes, exc: type[DecodeError], offset: int, words: str) -> None:
    with pytest.raises(exc) as info:
        get_codec(TS, typename, "jazzy").avro_to_cdr(body)
    assert info.value.typename == typename
    assert info.value.offset == offset
    assert words in info.value.reason


def test_fixed_array_with_wrong_item_count() -> None:
    codec = get_codec(TS, "sensor_msgs/msg/Imu", "jazzy")
    good = codec.cdr_to_avro(imu())
    # orientation_covariance announces 9 doubles; rewrite it as 8 items (still well-formed Avro)
    at = good.index(b"\x12\x00\x00")
    bad = good[:at] + zz(8) + good[at + 1 : at + 1 + 64] + good[at + 1 + 72 :]
    with pytest.raises(DecodeError) as info:
        codec.avro_to_cdr(bad)
    assert "orientation_covariance" in info.value.reason
    assert info.value.offset == at


def test_bounded_sequence_over_its_bound() -> None:
    ts = load_typestore("jazzy")
    from fleetlink.schemas.typestore import types_from_msg

    ts.register(types_from_msg("int32[<=2] xs\nstring<=3 s\n", "t_msgs/msg/Bounded"))
    codec = get_codec(ts, "t_msgs/msg/Bounded", "jazzy")
    too_many = b"\x00\x01\x00\x00" + struct.pack("<4i", 3, 1, 2, 3) + struct.pack("<I", 1) + b"\x00"
    with pytest.raises(DecodeError, match="bound 2"):
        codec.cdr_to_avro(too_many)
    with pytest.raises(DecodeError, match="bound 2"):
        codec.avro_to_cdr(zz(3) + zz(1) * 3 + b"\x00" + zz(0))
    with pytest.raises(DecodeError, match="bound 3"):
        codec.avro_to_cdr(b"\x00" + zz(4) + b"abcd")


def test_unknown_type() -> None:
    with pytest.raises(UnknownTypeError) as info:
        get_codec(TS, "nope_msgs/msg/Nothing", "jazzy")
    assert info.value.typename == "nope_msgs/msg/Nothing"


@pytest.mark.parametrize("typename", message_types(TS))
@settings(max_examples=20, deadline=None)
@given(payload=st.binary(max_size=96), header=st.sampled_from([b"\x00\x01\x00\x00", b"\x00\x00\x00\x00"]))
def test_garbage_never_leaks_low_level_errors(typename: str, payload: bytes, header: bytes) -> None:
    codec = get_codec(TS, typename, "jazzy")
    data = header + payload
    avro, error = _outcome(codec.cdr_to_avro, data)
    try:
        decoded: object = codec.decode(data)
    except SchemaError as exc:
        decoded = exc
    if error is not None:
        assert isinstance(error, DecodeError)
        assert isinstance(decoded, DecodeError)
        assert (decoded.offset, decoded.reason) == (error.offset, error.reason)
        assert error.typename == typename
        assert 0 <= error.offset <= len(data)
    else:
        # whatever decodes must convert back and forth consistently
        assert codec.cdr_to_avro(codec.avro_to_cdr(avro)) == avro
        assert same(decoded, codec.read_avro(avro))
    _, error = _outcome(codec.avro_to_cdr, payload)
    if error is not None:
        assert isinstance(error, DecodeError)
        assert 0 <= error.offset <= len(payload)


def _outcome(func: Callable[[bytes], bytes], data: bytes) -> tuple[bytes, SchemaError | None]:
    try:
        return func(data), None
    except SchemaError as exc:
        return b"", exc


@pytest.mark.parametrize(
    ("typename", "datum", "words"),
    [
        ("std_msgs/msg/UInt64", {"data": 2**63}, "OverflowError"),
        ("std_msgs/msg/Int32", {"other": 1}, "data"),
        ("std_msgs/msg/String", {"data": 5}, "data"),
    ],
)
def test_encode_datum_errors(typename: str, datum: dict[str, Any], words: str) -> None:
    with pytest.raises(EncodeError) as info:
        get_codec(TS, typename, "jazzy").encode_datum(datum)
    assert info.value.typename == typename
    assert words in info.value.reason
