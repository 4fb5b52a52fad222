"""The native converter (``fleetlink._native``) writes exactly what the generated Python one
writes: for every message type (generated values, as in the round-trip test), for every message
of the recorded bags, and for damaged input (where it may refuse more, never differ)."""

from __future__ import annotations

import random
from functools import cache

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from rosbags.rosbag2 import Reader

from fleetlink._native import AvroProgram
from fleetlink.schemas.codec import Codec, get_codec
from fleetlink.schemas.errors import SchemaError
from fleetlink.schemas.layout_program import layout_program
from fleetlink.schemas.typestore import load_typestore
from tests.paths import HUSKY, TURTLEBOT3
from tests.unit.schemas.ros_values import message
from tests.unit.schemas.test_schemas_roundtrip import TS, TYPES


@cache
def native(typename: str) -> AvroProgram:
    return AvroProgram(layout_program(get_codec(TS, typename, "jazzy").layout))


def python_or_none(codec: Codec, cdr: bytes) -> bytes | None:
    try:
        return codec.cdr_to_avro(cdr)
    except SchemaError:
        return None


@pytest.mark.parametrize("typename", TYPES)
@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_same_avro_as_the_python_converter(typename: str, data: st.DataObject) -> None:
    obj = data.draw(message(TS, typename))
    cdr = bytes(TS.serialize_cdr(obj, typename))
    codec = get_codec(TS, typename, "jazzy")
    assert native(typename).convert(cdr) == codec.cdr_to_avro(cdr)
    # big-endian payloads are left to the Python path
    assert native(typename).convert(bytes(TS.serialize_cdr(obj, typename, little_endian=False))) is None


@pytest.mark.parametrize("bag", [HUSKY, TURTLEBOT3], ids=["husky", "turtlebot3"])
def test_every_recorded_message(bag: object) -> None:
    ts = load_typestore("humble")
    seen = 0
    with Reader(bag) as reader:  # type: ignore[arg-type]
        for connection, _stamp, raw in reader.messages():
            codec = get_codec(ts, connection.msgtype, "humble")
            program = AvroProgram(layout_program(codec.layout))
            assert program.convert(raw) == codec.cdr_to_avro(raw), connection.topic
            seen += 1
    assert seen > 10_000


@pytest.mark.parametrize(
    "typename",
    [
        "sensor_msgs/msg/Imu",
        "sensor_msgs/msg/JointState",
        "diagnostic_msgs/msg/DiagnosticArray",
        "t_msgs/msg/Outer",
        "sensor_msgs/msg/PointCloud2",
    ],
)
@settings(max_examples=60, deadline=None)
@given(data=st.data(), seed=st.integers(0, 2**32 - 1))
def test_damaged_input_is_refused_or_converted_the_same(
    typename: str, data: st.DataObject, seed: int
) -> None:
    obj = data.draw(message(TS, typename))
    cdr = bytearray(TS.serialize_cdr(obj, typename))
    rng = random.Random(seed)
    for _ in range(rng.randint(1, 4)):
        action = rng.random()
        if action < 0.5 and len(cdr) > 4:
            cdr[rng.randrange(4, len(cdr))] = rng.randrange(256)
        elif action < 0.75:
            del cdr[rng.randrange(4, len(cdr) + 1) :]
        else:
            cdr += bytes(rng.randrange(256) for _ in range(rng.randint(1, 8)))
    damaged = bytes(cdr)
    assert native(typename).convert(damaged) == python_or_none(get_codec(TS, typename, "jazzy"), damaged)


def test_a_program_that_is_not_one_is_refused() -> None:
    for code in (b"", b"\x09", b"\x03\x01\x00", b"\x01\x0d", b"\x04\x00\x01\x00\x00\x00\x00\x00\x00\x00"):
        with pytest.raises(ValueError, match="layout"):
            AvroProgram(code)
