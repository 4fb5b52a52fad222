"""The call envelope and outcome batches: round trips and every way bytes can be wrong."""

from __future__ import annotations

import json
import struct
import zlib
from dataclasses import replace

import pytest

from fleetlink.wire.calls import (
    MAGIC,
    CallEnvelope,
    Outcome,
    OutcomeBatch,
    call_key,
    decode_call,
    decode_outcomes,
    encode_call,
    encode_outcomes,
    outcome_key,
)
from fleetlink.wire.errors import EnvelopeError

pytestmark = pytest.mark.unit

CDR = b"\x00\x01\x00\x00\x01\x00\x00\x00"
SERVICE = CallEnvelope(
    "service",
    "req-1",
    "tb4_01",
    "/tb4_01/e_stop",
    "irobot_create_msgs/srv/EStop",
    "estop",
    1000,
    6000,
    CDR,
    "t:0:5",
)
GOAL = CallEnvelope(
    "goal",
    "2f1c3e4a-0000-4000-8000-000000000001",
    "tb4_01",
    "/tb4_01/dock",
    "irobot_create_msgs/action/Dock",
    "dock",
    1000,
    61_000,
    b"\x00\x01\x00\x00\x00",
)
CANCEL = replace(GOAL, kind="cancel", payload=b"")


@pytest.mark.parametrize("env", [SERVICE, GOAL, CANCEL])
def test_call_round_trip(env: CallEnvelope) -> None:
    assert decode_call(encode_call(env)) == env


def test_large_call_is_compressed_and_still_decodes() -> None:
    env = replace(SERVICE, payload=b"\x00\x01\x00\x00" + b"a" * 4000)
    data = encode_call(env)
    assert data[4] == 1
    assert len(data) < 500
    assert decode_call(data) == env


def _raw(header: dict[str, object], payload: bytes = CDR) -> bytes:
    head = json.dumps(header).encode()
    return MAGIC + b"\x01\x00" + struct.pack(">I", len(head)) + head + payload


GOOD = {
    "kind": "service",
    "id": "x",
    "robot": "tb4_01",
    "name": "/tb4_01/e_stop",
    "type": "irobot_create_msgs/srv/EStop",
    "mapping": "estop",
    "issued": 1,
    "deadline": 2,
}


@pytest.mark.parametrize(
    ("data", "reason"),
    [
        (b"FLC\x01\x00", "does not start with"),
        (b"FLK\x02\x00xxxx", "version 2"),
        (b"FLK\x01\x80xxxx", "unknown flags"),
        (b"FLK\x01\x01garbage", "zlib"),
        (b"FLK\x01\x00\x00\x00", "truncated"),
        (MAGIC + b"\x01\x00" + struct.pack(">I", 99) + b"{}", "runs past the end"),
        (_raw({**GOOD, "kind": "topic"}), "kind 'topic'"),
        (_raw({**GOOD, "id": ""}), "'id' must not be empty"),
        (_raw({**GOOD, "id": "x" * 201}), "1 to 200 characters"),
        (_raw({**GOOD, "robot": "a/*"}), "robot"),
        (_raw({**GOOD, "mapping": "a/b"}), "mapping"),
        (_raw({**GOOD, "name": "no slash"}), "ROS name"),
        (_raw({**GOOD, "type": "irobot_create_msgs/action/Dock"}), "must look like 'package/srv/Type'"),
        (_raw({**GOOD, "deadline": 0}), "not a time span"),
        (_raw({**GOOD, "issued": -1}), "must not be negative"),
        (_raw({**GOOD, "issued": "1"}), "must be an integer"),
        (_raw(GOOD, b"\x00"), "CDR payload"),
        (_raw({**GOOD, "kind": "cancel", "type": "irobot_create_msgs/action/Dock"}), "carries no payload"),
        (MAGIC + b"\x01\x00" + struct.pack(">I", 2) + b"[]", "not a JSON object"),
    ],
)
def test_bad_call_envelopes_name_the_problem(data: bytes, reason: str) -> None:
    with pytest.raises(EnvelopeError, match="call envelope") as info:
        decode_call(data)
    assert reason in str(info.value)


def test_encoding_checks_too() -> None:
    with pytest.raises(EnvelopeError, match="package/action/Type"):
        encode_call(replace(GOAL, ros_type="std_srvs/srv/Trigger"))


OUTCOMES = (
    Outcome("reply", "req-1", "tb4_01", "estop", "ok", 5000, "", CDR, 1000, "warehouse-a"),
    Outcome("reply", "req-2", "tb4_01", "estop", "timeout", 6000, "no response within 5 s"),
    Outcome("feedback", GOAL.call_id, "tb4_01", "dock", "feedback", 7000, payload=b"\x00\x01\x00\x00\x01"),
    Outcome("result", GOAL.call_id, "tb4_01", "dock", "succeeded", 8000, payload=b"\x00\x01\x00\x00\x01"),
    Outcome(
        "cancel", GOAL.call_id, "tb4_01", "dock", "cancel-terminated", 9000, "the goal had already finished"
    ),
)


def test_outcome_batch_round_trip_and_compression() -> None:
    batch = OutcomeBatch("rep-1", "warehouse-a", OUTCOMES)
    data = encode_outcomes(batch)
    assert data[:1] != b"{"  # compressed: larger than 160 bytes
    assert decode_outcomes(data) == batch
    empty = OutcomeBatch("rep-1", "warehouse-a")
    assert decode_outcomes(encode_outcomes(empty)) == empty


def _batch(outcome: dict[str, object]) -> bytes:
    return json.dumps({"repeater": "r", "site": "s", "outcomes": [outcome]}).encode()


GOOD_OUTCOME = {"kind": "reply", "id": "x", "robot": "tb4_01", "mapping": "estop", "status": "ok", "at": 1}


@pytest.mark.parametrize(
    ("data", "reason"),
    [
        (zlib.compress(b"[]"), "not a JSON object"),
        (b"\x78garbage", "zlib"),
        (json.dumps({"repeater": "r", "site": "s"}).encode(), "'outcomes' must be a list"),
        (_batch({**GOOD_OUTCOME, "kind": "status"}), "kind 'status'"),
        (_batch({**GOOD_OUTCOME, "status": "succeeded"}), "status 'succeeded'"),
        (_batch({**GOOD_OUTCOME, "kind": "cancel", "status": "ok"}), "status 'ok'"),
        (_batch({**GOOD_OUTCOME, "cdr": "!!"}), "not base64"),
        (_batch({**GOOD_OUTCOME, "robot": "*"}), "robot"),
        (_batch({**GOOD_OUTCOME, "kind": "feedback", "status": "feedback"}), "feedback's CDR"),
        (_batch({**GOOD_OUTCOME, "at": -5}), "must not be negative"),
        (_batch([1]), "not a JSON object"),  # type: ignore[arg-type]
    ],
)
def test_bad_outcomes_name_the_problem(data: bytes, reason: str) -> None:
    with pytest.raises(EnvelopeError) as info:
        decode_outcomes(data)
    assert reason in str(info.value)


def test_keys() -> None:
    assert call_key("warehouse-a", "tb4_01", "estop") == "fleetlink/warehouse-a/call/tb4_01/estop"
    assert outcome_key("warehouse-a", "rep-1") == "fleetlink/warehouse-a/call-outcome/rep-1"
