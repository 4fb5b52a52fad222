"""Record groups: what the spool stores and the WAN carries, one unit for many records."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from fleetlink.wire import WireError
from fleetlink.wire.groups import encode_group, group_count, group_head, group_payloads, split_group
from fleetlink.wire.records import PayloadTemplate

FP_A, FP_B = b"A" * 8, b"B" * 8


def record(fp: bytes, n: int) -> bytes:
    return PayloadTemplate("t", b"k").payload(b"\xc3\x01" + fp + bytes([n % 256]) * n, n, n)


def test_head_lists_the_schemas_its_records_use() -> None:
    payloads = [record(FP_B, 1), record(FP_A, 2), record(FP_B, 3)]
    group = encode_group(payloads)
    count, fps, _start = group_head(group)
    assert (count, fps) == (3, (FP_A, FP_B))
    assert group_count(group) == 3
    assert group_payloads(group) == payloads


@given(st.lists(st.binary(max_size=40), min_size=1, max_size=50), st.integers(1, 20), st.integers(1, 300))
def test_split_keeps_every_record_in_order_within_the_limits(
    payloads: list[bytes], max_records: int, max_bytes: int
) -> None:
    parts = split_group(encode_group(payloads), max_records, max_bytes)
    assert [p for part in parts for p in group_payloads(part)] == payloads
    for part in parts:
        records = group_payloads(part)
        assert len(records) <= max_records
        assert len(records) == 1 or sum(len(r) + 4 for r in records) <= max_bytes


@pytest.mark.parametrize(
    ("group", "reason"),
    [
        (b"\x01\x00", "at least 6 bytes"),
        (b"\x00\x00\x00\x00\x00\x00", "at least one record"),
        (b"\x01\x00\x00\x00\x02\x00" + b"x" * 8, "too short for 2 fingerprints"),
        (b"\x02\x00\x00\x00\x00\x00\x01\x00\x00\x00a", "truncated before record 2 of 2"),
        (b"\x01\x00\x00\x00\x00\x00\x05\x00\x00\x00a", "runs past its group"),
        (b"\x01\x00\x00\x00\x00\x00\x01\x00\x00\x00ab", "1 bytes after the 1 records"),
    ],
)
def test_malformed_groups_say_why(group: bytes, reason: str) -> None:
    with pytest.raises(WireError, match=reason):
        group_payloads(group)
