"""The record size the uplink's limit and the edge's check share."""

from __future__ import annotations

from fleetlink.wire.limits import HEADER_OVERHEAD, RECORD_OVERHEAD, kafka_record_bytes


def test_counts_key_value_and_every_header() -> None:
    assert kafka_record_bytes(0, 0, []) == RECORD_OVERHEAD
    headers = [("fleetlink.robot", b"tb4_01"), ("fleetlink.site", b"\xc3\xa9")]
    expected = RECORD_OVERHEAD + 6 + 1000 + 2 * HEADER_OVERHEAD + len("fleetlink.robot") + 6 + 14 + 2
    assert kafka_record_bytes(6, 1000, headers) == expected


def test_header_names_are_counted_in_utf8_bytes() -> None:
    assert kafka_record_bytes(0, 0, [("é", b"")]) == RECORD_OVERHEAD + HEADER_OVERHEAD + 2
