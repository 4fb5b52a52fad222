"""fleetlink.console.envelope: the admin space's reply envelopes, read and written."""

from __future__ import annotations

import json

import pytest

from fleetlink.console.envelope import Envelope, failure, from_parts, parse


def test_an_answer_and_a_refusal_round_trip() -> None:
    ok = parse(json.dumps({"status": 200, "site": "a", "edge_id": "e", "body": [1]}).encode())
    assert ok == Envelope(status=200, site="a", edge_id="e", body=[1])
    assert ok.ok
    assert ok.as_dict() == {"status": 200, "site": "a", "edge_id": "e", "body": [1]}
    problem = {"path": "to", "message": "bad", "config_path": "mappings[0].to"}
    refused = parse(
        json.dumps(
            {"status": 422, "site": "a", "edge_id": "e", "error": "invalid", "problems": [problem, "junk"]}
        ).encode()
    )
    assert (refused.ok, refused.error, refused.problems) == (False, "invalid", (problem,))
    assert refused.as_dict()["problems"] == [problem]


@pytest.mark.parametrize(
    ("payload", "message"),
    [
        (b"not json", "unreadable reply on k"),
        (b"\xff\xfe", "unreadable reply on k"),
        (b"[1]", "no status"),
        (b'{"status": "200"}', "no status"),
        (b"{}", "no status"),
    ],
)
def test_unreadable_replies_become_502(payload: bytes, message: str) -> None:
    env = parse(payload, key="k")
    assert env.status == 502
    assert env.error is not None
    assert message in env.error


def test_parts_and_failures() -> None:
    assert from_parts(201, {"body": {"status": "created"}}, site="s", edge_id="e").body == {
        "status": "created"
    }
    assert from_parts(404, {"error": "no", "problems": []}, site="s", edge_id="e").error == "no"
    assert failure(504, "nobody answered", site="s") == Envelope(
        status=504, site="s", error="nobody answered"
    )
    assert parse(b'{"status": 200, "site": 3, "body": null}').site == ""
