"""The uplink <-> repeater wire contract: round trips and every way bytes can be wrong."""

from __future__ import annotations

import json
import struct
import zlib
from dataclasses import replace

import pytest

from fleetlink.wire.commands import (
    MAGIC,
    CommandEnvelope,
    CommandReply,
    StatusAck,
    StatusBatch,
    StatusEvent,
    decode_envelope,
    decode_reply,
    decode_status_ack,
    decode_status_batch,
    encode_envelope,
    encode_reply,
    encode_status_ack,
    encode_status_batch,
)
from fleetlink.wire.envelope import FLAG_ZLIB
from fleetlink.wire.errors import EnvelopeError

SCHEMA = json.dumps({"type": "record", "name": "R", "fields": [{"name": "x", "type": "long"}] * 1}) * 40
ENV = CommandEnvelope(
    command_id="fleet.cmd:0:42",
    robot="tb4_01",
    ros_topic="/tb4_01/cmd_lightring",
    ros_type="irobot_create_msgs/msg/LightringLeds",
    mapping="lightring",
    issued_at_ms=1_700_000_000_000,
    lease_until_ms=1_700_000_010_000,
    period_ms=1000,
    schema_fp=b"\x01" * 8,
    body=b"\x02\x04body",
    schema=SCHEMA,
    qos="::,10:,:,:,,",
    order=42,
    source="fleet.cmd:0:42",
)


@pytest.mark.parametrize(
    "env",
    [
        ENV,
        ENV.without_schema(),
        replace(ENV, qos=None, source="", order=0),
        replace(ENV, robot="fleet/tb4_01", ros_topic="/fleet/tb4_01/cmd", command_id="ü-id"),
        replace(ENV, body=b""),
    ],
)
def test_envelope_round_trip(env: CommandEnvelope) -> None:
    assert decode_envelope(encode_envelope(env)) == env


def test_large_envelopes_are_compressed_small_ones_not() -> None:
    big, small = encode_envelope(ENV), encode_envelope(ENV.without_schema(), compress_above=1 << 20)
    assert big[4] == FLAG_ZLIB
    assert len(big) < len(SCHEMA)
    assert small[4] == 0
    assert decode_envelope(small) == ENV.without_schema()
    assert ENV.lease_ms == 10_000
    assert ENV.with_schema("x").schema == "x"


VALUE = b"\xc3\x01" + b"\x01" * 8 + b"body"


def _raw(header: dict[str, object], value: bytes = VALUE) -> bytes:
    head = json.dumps(header).encode()
    return MAGIC + bytes((1, 0)) + struct.pack(">I", len(head)) + head + value


GOOD_HEADER: dict[str, object] = {
    "id": "c1",
    "robot": "tb4_01",
    "topic": "/tb4_01/cmd",
    "type": "p/msg/T",
    "mapping": "m",
    "issued": 1000,
    "until": 2000,
    "period": 100,
    "order": 0,
    "source": "",
}


def test_the_hand_built_header_is_valid() -> None:
    assert decode_envelope(_raw(GOOD_HEADER)).command_id == "c1"


@pytest.mark.parametrize(
    ("data", "reason"),
    [
        (b"", "does not start with"),
        (b"XYZ\x01\x00", "does not start with"),
        (MAGIC + b"\x02\x00", "version 2"),
        (MAGIC + b"\x01\x80", "unknown flags"),
        (MAGIC + b"\x01\x01notzlib", "bad zlib"),
        (MAGIC + b"\x01\x00\x00\x00", "truncated before the header length"),
        (MAGIC + b"\x01\x00\x00\x00\x10\x00{}", "runs past the end"),
        (MAGIC + b"\x01\x00\x00\x00\x00\x03[1]", "not a JSON object"),
        (MAGIC + b"\x01\x00\x00\x00\x00\x02{x", "not JSON"),
        (_raw(GOOD_HEADER, value=b"\x00\x01" + b"\x00" * 8), "not an Avro single-object value"),
        (_raw(GOOD_HEADER, value=b"\xc3\x01\x00"), "too short"),
        (_raw({**GOOD_HEADER, "id": ""}), "'id' must not be empty"),
        (_raw({**GOOD_HEADER, "robot": 7}), "'robot' must be a string"),
        (_raw({k: v for k, v in GOOD_HEADER.items() if k != "topic"}), "'topic' must be a string"),
        (_raw({**GOOD_HEADER, "issued": "1"}), "'issued' must be an integer"),
        (_raw({**GOOD_HEADER, "issued": True}), "'issued' must be an integer"),
        (_raw({**GOOD_HEADER, "order": -1}), "'order' must not be negative"),
        (_raw({**GOOD_HEADER, "schema": 5}), "'schema' must be a string"),
        (_raw({**GOOD_HEADER, "robot": "tb4 01"}), "cannot be used in a key expression"),
        (_raw({**GOOD_HEADER, "robot": "tb4/*"}), "cannot be used in a key expression"),
        (_raw({**GOOD_HEADER, "mapping": "a/b"}), "must be one key chunk"),
        (_raw({**GOOD_HEADER, "topic": "no_slash//x"}), "ROS topic"),
        (_raw({**GOOD_HEADER, "type": "p/T"}), "package/msg/Type"),
        (_raw({**GOOD_HEADER, "until": 999}), "is not a time span"),
        (_raw({**GOOD_HEADER, "period": 0}), "period 0 ms must be positive"),
    ],
)
def test_malformed_envelopes(data: bytes, reason: str) -> None:
    with pytest.raises(EnvelopeError, match=reason) as info:
        decode_envelope(data)
    assert info.value.data == data[:256]


def test_inflating_beyond_the_limit_is_refused() -> None:
    bomb = MAGIC + bytes((1, FLAG_ZLIB)) + zlib.compress(b"\x00" * (9 << 20))
    with pytest.raises(EnvelopeError, match="inflates beyond"):
        decode_envelope(bomb)


def test_encoding_checks_the_envelope_too() -> None:
    with pytest.raises(EnvelopeError, match="has 1 bytes, not 8"):
        encode_envelope(replace(ENV, schema_fp=b"\x01"))
    with pytest.raises(EnvelopeError, match="1 to 1000 characters"):
        encode_envelope(replace(ENV, command_id="x" * 1001))


@pytest.mark.parametrize(
    "reply",
    [
        CommandReply("c1", "tb4_01", "applied", "", "site-a", "rep-1"),
        CommandReply("c1", "tb4_01", "need-schema", "writer schema 0101 unknown here"),
        CommandReply("c1", "tb4_01", "duplicate"),
    ],
)
def test_reply_round_trip(reply: CommandReply) -> None:
    assert decode_reply(encode_reply(reply)) == reply


@pytest.mark.parametrize(
    ("data", "reason"),
    [
        (b"[]", "not a JSON object"),
        (b'{"id": "c", "robot": "r", "result": "maybe"}', "result 'maybe'"),
        (b'{"id": "c", "robot": "r"}', "'result' must be a string"),
    ],
)
def test_malformed_replies(data: bytes, reason: str) -> None:
    with pytest.raises(EnvelopeError, match=reason):
        decode_reply(data)


def test_status_batch_and_ack_round_trip() -> None:
    events = (
        StatusEvent("c1", "tb4_01", "/tb4_01/cmd", "delivered", 5, "site-a", "publish #1"),
        StatusEvent("c2", "tb4_02", "/tb4_02/cmd", "expired", 6),
    )
    for batch in (
        StatusBatch("rep-1", "site-a", events),
        StatusBatch("rep-1", "site-a"),
        StatusBatch("rep-1", "site-a", events * 50),
    ):
        assert decode_status_batch(encode_status_batch(batch)) == batch
        assert decode_status_batch(encode_status_batch(batch, compress_above=1 << 20)) == batch
    big = StatusBatch("rep-1", "site-a", events * 50)
    assert len(encode_status_batch(big)) * 5 < len(encode_status_batch(big, compress_above=1 << 20))
    assert decode_status_ack(encode_status_ack(StatusAck(2, "ok"))) == StatusAck(2, "ok")


@pytest.mark.parametrize(
    ("data", "reason"),
    [
        (b'{"repeater": "r", "site": "s"}', "'events' must be a list"),
        (b'{"repeater": "r", "site": "s", "events": [1]}', "not a JSON object"),
        (
            b'{"repeater": "r", "site": "s", "events": [{"id": "c", "robot": "r", "topic": "/t", '
            b'"status": "lost", "at": 1}]}',
            "status 'lost'",
        ),
        (b'{"repeater": "", "site": "s", "events": []}', "'repeater' must not be empty"),
        (b"x\x9cnot zlib", "bad zlib data"),
        (zlib.compress(b"[1]"), "not a JSON object"),
    ],
)
def test_malformed_status_batches(data: bytes, reason: str) -> None:
    with pytest.raises(EnvelopeError, match=reason):
        decode_status_batch(data)


def test_unknown_status_is_refused_when_encoding() -> None:
    bad = StatusEvent("c", "r", "/t", "lost", 1)  # type: ignore[arg-type]
    with pytest.raises(EnvelopeError, match="status 'lost'"):
        encode_status_batch(StatusBatch("r", "s", (bad,)))
