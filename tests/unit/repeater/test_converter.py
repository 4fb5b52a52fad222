"""Avro command values -> CDR: the fast path, schema resolution, and what cannot be converted."""

from __future__ import annotations

import copy
import io
import json
from dataclasses import replace
from typing import Any

import fastavro
import pytest

from fleetlink.repeater.converter import Converter
from fleetlink.repeater.errors import ConversionError
from fleetlink.roswire.sim.messages import LIGHTRING, MessageFactory
from fleetlink.schemas.codec import get_codec
from fleetlink.schemas.single_object import fingerprint
from fleetlink.schemas.typestore import load_typestore
from fleetlink.wire.commands import CommandEnvelope
from tests.paths import IROBOT

TS = load_typestore("jazzy", [IROBOT])
CODEC = get_codec(TS, LIGHTRING, "jazzy")
MESSAGE = MessageFactory(TS, "tb4_01").lightring(((255, 0, 0),) * 6, True, 12.5)
CDR = bytes(TS.serialize_cdr(MESSAGE, LIGHTRING))
ENV = CommandEnvelope(
    "c1",
    "tb4_01",
    "/tb4_01/cmd_lightring",
    LIGHTRING,
    "lightring",
    0,
    10_000,
    1000,
    fingerprint(CODEC.schema),
    CODEC.cdr_to_avro(CDR),
)


def write(schema: dict[str, Any], datum: dict[str, Any]) -> bytes:
    out = io.BytesIO()
    fastavro.schemaless_writer(out, fastavro.parse_schema(copy.deepcopy(schema)), datum)
    return out.getvalue()


def test_own_schema_converts_byte_exact() -> None:
    converter = Converter(TS, "jazzy")
    assert converter.is_own_schema(ENV)
    assert converter.to_cdr(ENV, None) == CDR


def test_an_evolved_writer_schema_is_resolved_to_the_ros_type() -> None:
    evolved = copy.deepcopy(CODEC.schema)
    evolved["fields"].append({"name": "reason", "type": "string", "default": ""})
    datum = {**CODEC.decode(CDR), "reason": "robot picked up"}
    env = replace(ENV, schema_fp=fingerprint(evolved), body=write(evolved, datum))
    converter = Converter(TS, "jazzy")
    assert not converter.is_own_schema(env)
    assert converter.to_cdr(env, json.dumps(evolved)) == CDR
    assert converter.to_cdr(env, json.dumps(evolved)) == CDR  # parsed writer cached


@pytest.mark.parametrize(
    ("change", "schema", "reason"),
    [
        ({"ros_type": "irobot_create_msgs/msg/Nope"}, None, "unknown ROS type"),
        ({"schema_fp": b"\x09" * 8}, None, "writer schema 0909090909090909 is unknown here"),
        ({"schema_fp": b"\x09" * 8}, "{not json", "writer schema is unusable"),
        (
            {"schema_fp": b"\x09" * 8},
            json.dumps({"type": "record", "name": "Other", "fields": [{"name": "x", "type": "long"}]}),
            "does not resolve",
        ),
        ({"body": b"\x02"}, None, "LightringLeds"),
    ],
)
def test_what_cannot_be_converted(change: dict[str, Any], schema: str | None, reason: str) -> None:
    env = replace(ENV, **change)
    with pytest.raises(ConversionError, match=reason) as info:
        Converter(TS, "jazzy").to_cdr(env, schema)
    assert info.value.command_id == "c1"
