"""Dead-letter records keep the raw bytes, the reason, the stage and where it was going."""

from __future__ import annotations

import hashlib

from fleetlink.uplink.dead_letter import dead_letter


def test_raw_bytes_and_reason_are_kept() -> None:
    dl = dead_letter(
        dlq_topic="dlq",
        stage="register",
        reason="incompatible: field removed",
        intended_topic="fleet.imu",
        key=b"tb4_01",
        raw=b"\xc3\x01abc",
        headers=[("fleetlink.robot", b"tb4_01")],
        timestamp_ms=42,
    )
    headers = dict(dl.headers)
    assert (dl.topic, dl.key, dl.value, dl.timestamp_ms) == ("dlq", b"tb4_01", b"\xc3\x01abc", 42)
    assert headers["fleetlink.dlq.stage"] == b"register"
    assert headers["fleetlink.dlq.reason"] == b"incompatible: field removed"
    assert headers["fleetlink.dlq.topic"] == b"fleet.imu"
    assert headers["fleetlink.robot"] == b"tb4_01"


def test_oversized_value_becomes_a_reference() -> None:
    raw = b"x" * 2_000_000
    dl = dead_letter(
        dlq_topic="dlq",
        stage="produce",
        reason="MSG_SIZE_TOO_LARGE",
        intended_topic="fleet.scan",
        key=None,
        raw=raw,
    )
    headers = dict(dl.headers)
    assert dl.value == b""
    assert headers["fleetlink.dlq.size"] == b"2000000"
    assert headers["fleetlink.dlq.sha256"] == hashlib.sha256(raw).hexdigest().encode()
