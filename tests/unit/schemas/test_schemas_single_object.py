"""Single-object encoding and Confluent framing."""

from __future__ import annotations

import pytest
from fastavro.schema import fingerprint as fastavro_fingerprint

from fleetlink.schemas.avro_schema import avro_schema
from fleetlink.schemas.single_object import (
    FramingError,
    canonical_form,
    confluent_frame,
    confluent_unframe,
    crc64_avro,
    fingerprint,
    frame,
    unframe,
)
from fleetlink.schemas.typestore import load_typestore, message_types

TS = load_typestore("jazzy")


@pytest.mark.parametrize(
    ("schema", "expected"),
    [
        # values from the Avro specification's fingerprint test data
        ('"int"', 0x7275D51A3F395C8F),
        ('"string"', 0x8F014872634503C7),
        ('"null"', 0x63DD24E7CC258F8A),
    ],
)
def test_crc64_avro_vectors(schema: str, expected: int) -> None:
    assert crc64_avro(schema.encode()) == expected


def test_empty_input_gives_the_seed() -> None:
    assert crc64_avro(b"") == 0xC15D213AA4D7A795


@pytest.mark.parametrize("typename", message_types(TS)[:60])
def test_fingerprint_agrees_with_fastavro(typename: str) -> None:
    schema = avro_schema(TS, typename, "jazzy")
    expected = bytes.fromhex(fastavro_fingerprint(canonical_form(schema), "CRC-64-AVRO"))
    assert fingerprint(schema) == expected


def test_documentation_does_not_change_the_fingerprint() -> None:
    schema = avro_schema(TS, "sensor_msgs/msg/Imu", "jazzy")
    humble = avro_schema(load_typestore("humble"), "sensor_msgs/msg/Imu", "humble")
    assert schema != humble  # the type hash property differs
    assert fingerprint(schema) == fingerprint(humble)


def test_frame_round_trip() -> None:
    fp = fingerprint(avro_schema(TS, "std_msgs/msg/String", "jazzy"))
    data = frame(fp, b"\x06abc")
    assert data[:2] == b"\xc3\x01"
    assert unframe(data) == (fp, b"\x06abc")


def test_confluent_round_trip() -> None:
    data = confluent_frame(258, b"body")
    assert data == b"\x00\x00\x00\x01\x02body"
    assert confluent_unframe(data) == (258, b"body")


@pytest.mark.parametrize(
    ("func", "data", "offset", "words"),
    [
        (unframe, b"\xc3\x01\x00", 3, "too short"),
        (unframe, b"\xc3\x02" + bytes(8), 0, "marker"),
        (confluent_unframe, b"\x00\x00", 2, "too short"),
        (confluent_unframe, b"\x01\x00\x00\x00\x01", 0, "magic"),
    ],
)
def test_bad_framing(func: object, data: bytes, offset: int, words: str) -> None:
    with pytest.raises(FramingError) as info:
        func(data)  # type: ignore[operator]
    assert info.value.offset == offset
    assert words in info.value.reason
    assert info.value.data == data


@pytest.mark.parametrize(("fp", "schema_id"), [(b"short", 1)])
def test_bad_arguments(fp: bytes, schema_id: int) -> None:
    with pytest.raises(FramingError):
        frame(fp, b"")
    with pytest.raises(FramingError):
        confluent_frame(-schema_id, b"")
