"""Telling the attachment layout and hash style of a network from what it sends."""

from __future__ import annotations

import pytest

from fleetlink.roswire.attachment import encode
from fleetlink.roswire.qos import DEFAULT
from fleetlink.roswire.tokens import EndpointInfo, EntityKind, endpoint_token, parse_token
from fleetlink.roswire.wire_detect import WireTally

V1 = encode(1, 2, bytes(16), 1)
V2 = encode(1, 2, bytes(16), 2)


def endpoint(type_hash: str) -> EndpointInfo:
    ep = parse_token(
        endpoint_token(
            domain=0,
            zid="ab",
            nid=0,
            eid=1,
            kind=EntityKind.PUBLISHER,
            namespace="/",
            node_name="n",
            topic="/t",
            typename="std_msgs/msg/String",
            type_hash=type_hash,
            qos=DEFAULT,
        )
    )
    assert isinstance(ep, EndpointInfo)
    return ep


@pytest.mark.parametrize(
    ("attachments", "version", "mixed"),
    [
        ([], None, False),
        ([V2, V2], 2, False),
        ([V1], 1, False),
        ([V1, V1, V2], 1, True),
        ([V1, V2], 2, True),
        ([None, b"junk"], None, False),
    ],
)
def test_attachment_verdict(attachments: list[bytes | None], version: int | None, mixed: bool) -> None:
    tally = WireTally()
    for raw in attachments:
        tally.observe_attachment(raw)
    verdict = tally.verdict()
    assert verdict.attachment_version == version
    assert verdict.mixed is mixed


def test_counts_by_kind() -> None:
    tally = WireTally()
    for raw in (V1, V2, None, b"junk"):
        tally.observe_attachment(raw)
    assert tally.verdict().attachments == {"v1": 1, "v2": 1, "none": 1, "unknown": 1}


@pytest.mark.parametrize(
    ("hashes", "style"),
    [
        ([], None),
        (["TypeHashNotSupported"], "humble"),
        (["RIHS01_" + "0" * 64, "TypeHashNotSupported", "RIHS01_" + "1" * 64], "rihs01"),
    ],
)
def test_hash_style(hashes: list[str], style: str | None) -> None:
    tally = WireTally()
    for h in hashes:
        tally.observe_endpoint(endpoint(h))
    assert tally.verdict().hash_style == style
    assert tally.verdict().endpoints == len(hashes)
