"""Avro datums ↔ JSON values: what ``fleetlink kafka echo`` prints goes back in through ``send``."""

from __future__ import annotations

import json
import math
from typing import Any

import pytest

from fleetlink.schemas.avro_json import from_json, to_json
from fleetlink.schemas.avro_schema import avro_schema
from fleetlink.schemas.confluent_values import ConfluentValues
from fleetlink.schemas.errors import DecodeError, EncodeError
from fleetlink.schemas.typestore import load_typestore
from tests.paths import IROBOT

KINDS: dict[str, Any] = {
    "type": "record",
    "name": "Kinds",
    "namespace": "test",
    "fields": [
        {"name": "flag", "type": "boolean"},
        {"name": "small", "type": "int"},
        {"name": "big", "type": "long"},
        {"name": "ratio", "type": "double"},
        {"name": "f", "type": "float"},
        {"name": "blob", "type": "bytes"},
        {"name": "name", "type": "string"},
        {"name": "colour", "type": {"type": "enum", "name": "Colour", "symbols": ["RED", "GREEN"]}},
        {"name": "id", "type": {"type": "fixed", "name": "Id", "size": 2}},
        {"name": "tags", "type": {"type": "map", "values": "long"}},
        {"name": "maybe", "type": ["null", "string"], "default": None},
        {
            "name": "points",
            "type": {
                "type": "array",
                "items": {"type": "record", "name": "P", "fields": [{"name": "x", "type": "float"}]},
            },
        },
        {"name": "first", "type": "P"},
        {"name": "again", "type": "test.Colour"},
    ],
}


def _kinds() -> dict[str, Any]:
    return {
        "flag": True,
        "small": -5,
        "big": 2**40,
        "ratio": math.nan,
        "f": -math.inf,
        "blob": b"\x00\xffhi",
        "name": "tb4_02",
        "colour": "GREEN",
        "id": b"\x01\x02",
        "tags": {"a": 1},
        "maybe": None,
        "points": [{"x": 1.5}, {"x": math.inf}],
        "first": {"x": 0.0},
        "again": "RED",
    }


def test_every_kind_goes_out_as_json_and_back_in() -> None:
    datum = _kinds()
    shown = to_json(datum)
    text = json.dumps(shown, allow_nan=False)  # strict JSON: no NaN literals
    assert shown["blob"] == "AP9oaQ=="
    assert shown["ratio"] == "NaN"
    assert shown["f"] == "-Infinity"
    assert shown["points"][1] == {"x": "Infinity"}
    back = from_json(KINDS, json.loads(text))
    assert math.isnan(back.pop("ratio"))
    expected = _kinds()
    del expected["ratio"]
    assert back == expected
    values = ConfluentValues(lambda _id: KINDS)
    framed = values.encode(7, KINDS, from_json(KINDS, json.loads(text)))
    assert framed[:5] == b"\x00\x00\x00\x00\x07"
    schema_id, decoded = values.decode(framed)
    assert schema_id == 7
    assert to_json(decoded) == shown


def test_bytes_also_as_a_list_and_defaults_fill_missing_fields() -> None:
    value = to_json(_kinds())
    value["blob"] = [0, 255, 104, 105]
    del value["maybe"]
    assert from_json(KINDS, value)["blob"] == b"\x00\xffhi"
    assert from_json(KINDS, value)["maybe"] is None


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"small": "x"}, "small: expected an int, got 'x'"),
        ({"small": True}, "small: expected an int, got True"),
        ({"small": 2**31}, "small: 2147483648 does not fit an Avro int"),
        ({"name": 12}, "name: expected a string, got 12 (quote it in YAML)"),
        ({"blob": "not base64!"}, "blob: expected base64 bytes"),
        ({"blob": [1, 256]}, "blob: expected base64 text or a list of 0-255 integers"),
        ({"id": "AQID"}, "id: expected 2 bytes, got 3"),
        ({"colour": "BLUE"}, "colour: expected one of ['RED', 'GREEN'], got 'BLUE'"),
        ({"points": [{"x": "fast"}]}, "points[0].x: expected a number (or NaN, Infinity, -Infinity)"),
        ({"points": [{"x": 1, "y": 2}]}, "points[0]: unknown field(s) ['y']; P has ['x']"),
        ({"first": None}, "first: expected a mapping (record P), got None"),
        ({"maybe": 3}, "maybe: matches no branch of the union"),
        ({"flag": None}, "flag: expected true or false, got None"),
    ],
)
def test_mistakes_are_named_by_their_path(change: dict[str, Any], message: str) -> None:
    value = {**to_json(_kinds()), **change}
    with pytest.raises(EncodeError, match=r"^cannot encode test\.Kinds: ") as caught:
        from_json(KINDS, value)
    assert message in str(caught.value)


def test_a_missing_field_without_default_is_named() -> None:
    value = to_json(_kinds())
    del value["first"]
    with pytest.raises(EncodeError, match="first: missing"):
        from_json(KINDS, value)


def test_fleetlinks_own_schemas_round_trip() -> None:
    schema = avro_schema(load_typestore("jazzy", [IROBOT]), "irobot_create_msgs/msg/LightringLeds", "jazzy")
    value = {
        "header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": ""},
        "leds": [{"red": 0, "green": 0, "blue": 255}] * 6,
        "override_system": True,
    }
    values = ConfluentValues(lambda _id: schema)
    assert to_json(values.decode(values.encode(3, schema, from_json(schema, value)))[1]) == value


def test_values_that_are_not_confluent_framed_or_too_long_are_refused() -> None:
    values = ConfluentValues(lambda _id: KINDS)
    with pytest.raises(DecodeError, match="magic byte"):
        values.decode(b"not avro")
    framed = values.encode(1, KINDS, from_json(KINDS, to_json(_kinds())))
    with pytest.raises(DecodeError, match="1 bytes left over"):
        values.decode(framed + b"\x00")
    with pytest.raises(DecodeError, match="schema id 1"):
        values.decode(framed[:-3])
