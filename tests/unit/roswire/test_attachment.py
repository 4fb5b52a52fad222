"""Attachment byte vectors (rmw_zenoh.md §4), also checked against zenoh-ext's own serializer."""

from __future__ import annotations

import pytest
from zenoh.ext import Int64, z_serialize

from fleetlink.roswire.attachment import V1_SIZE, V2_SIZE, Attachment, decode, detect_version, encode
from fleetlink.roswire.errors import AttachmentError

GID = bytes(range(16))
V2_VECTOR = bytes.fromhex("010000000000000000002a36fe9c971710000102030405060708090a0b0c0d0e0f")
V1_VECTOR = bytes.fromhex(
    "0f73657175656e63655f6e756d626572"
    "0100000000000000"
    "10736f757263655f74696d657374616d70"
    "0200000000000000"
    "0a736f757263655f676964"
    "10" + "00" * 16
)


@pytest.mark.parametrize(
    ("attachment", "raw"),
    [
        (Attachment(1, 1_700_000_000_000_000_000, GID, 2), V2_VECTOR),
        (Attachment(1, 2, bytes(16), 1), V1_VECTOR),
        (
            Attachment(2**63 - 1, -1, b"\xff" * 16, 2),
            b"\xff" * 7 + b"\x7f" + b"\xff" * 8 + b"\x10" + b"\xff" * 16,
        ),
    ],
)
def test_vectors_round_trip(attachment: Attachment, raw: bytes) -> None:
    assert attachment.encode() == raw
    assert decode(raw) == attachment


def test_sizes() -> None:
    assert len(V2_VECTOR) == V2_SIZE == 33
    assert len(V1_VECTOR) == V1_SIZE == 77


@pytest.mark.parametrize(("seq", "ts"), [(1, 1_700_000_000_000_000_000), (12345, 1), (2**62, 2**62)])
def test_v2_matches_zenoh_ext_serialization(seq: int, ts: int) -> None:
    expected = z_serialize((Int64(seq), Int64(ts), GID)).to_bytes()
    assert encode(seq, ts, GID, 2) == expected


@pytest.mark.parametrize(("seq", "ts"), [(1, 2), (99, 1_800_000_000_000_000_000)])
def test_v1_matches_zenoh_ext_serialization(seq: int, ts: int) -> None:
    expected = z_serialize(
        ("sequence_number", Int64(seq), "source_timestamp", Int64(ts), "source_gid", GID)
    ).to_bytes()
    assert encode(seq, ts, GID, 1) == expected


@pytest.mark.parametrize(
    ("raw", "version"),
    [(V2_VECTOR, 2), (V1_VECTOR, 1), (b"", None), (V2_VECTOR[:-1], None), (b"\x00" * 77, None)],
)
def test_detect_version(raw: bytes, version: int | None) -> None:
    assert detect_version(raw) == version


@pytest.mark.parametrize(
    ("raw", "reason"),
    [
        (b"", "length 0"),
        (V2_VECTOR[:32], "length 32"),
        (V2_VECTOR + b"\x00", "length 34"),
        (V2_VECTOR[:16] + b"\x0f" + V2_VECTOR[17:], "GID length prefix is 15"),
        (b"\x00" * 77, "no 'sequence_number' label"),
        (V1_VECTOR.replace(b"source_gid", b"source_xxx"), "labels"),
        (V1_VECTOR[:-17] + b"\x11" + V1_VECTOR[-16:], "GID length prefix is 17"),
        (b"garbage bytes", "length 13"),
    ],
)
def test_broken_attachments_raise_with_bytes(raw: bytes, reason: str) -> None:
    with pytest.raises(AttachmentError, match=reason) as info:
        decode(raw)
    assert info.value.raw == raw


@pytest.mark.parametrize(
    ("gid", "seq", "version"),
    [(b"\x00" * 15, 1, 2), (b"\x00" * 17, 1, 2), (GID, 2**63, 2), (GID, 1, 3)],
)
def test_encode_rejects(gid: bytes, seq: int, version: int) -> None:
    with pytest.raises(AttachmentError):
        encode(seq, 0, gid, version)  # type: ignore[arg-type]
