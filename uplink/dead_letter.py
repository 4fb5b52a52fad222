"""Dead-letter records: what could not be delivered, with its raw bytes and the reason.

Every dead-letter record keeps the original key and headers, carries the raw bytes as its
value (or, when the value itself is too large for Kafka, a SHA-256 reference and the size),
and says in headers which stage refused it, why, and where it was going.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass

HEADER_REASON = "fleetlink.dlq.reason"
HEADER_STAGE = "fleetlink.dlq.stage"
HEADER_TOPIC = "fleetlink.dlq.topic"
HEADER_SIZE = "fleetlink.dlq.size"
HEADER_SHA256 = "fleetlink.dlq.sha256"
HEADER_TRUNCATED = "fleetlink.dlq.truncated"


@dataclass(frozen=True, slots=True)
class DeadLetter:
    topic: str
    key: bytes | None
    value: bytes
    headers: list[tuple[str, bytes]]
    timestamp_ms: int


def dead_letter(
    *,
    dlq_topic: str,
    stage: str,
    reason: str,
    intended_topic: str,
    key: bytes | None,
    raw: bytes,
    headers: Sequence[tuple[str, bytes]] = (),
    timestamp_ms: int = 0,
    max_value_bytes: int = 900_000,
) -> DeadLetter:
    """Build the dead-letter record for ``raw``; values above ``max_value_bytes`` become a reference."""
    extra = [
        (HEADER_STAGE, stage.encode()),
        (HEADER_REASON, reason.encode("utf-8", "replace")[:2000]),
        (HEADER_TOPIC, intended_topic.encode("utf-8", "replace")),
        (HEADER_SIZE, str(len(raw)).encode()),
    ]
    value = raw
    if len(raw) > max_value_bytes:
        extra.append((HEADER_SHA256, hashlib.sha256(raw).hexdigest().encode()))
        extra.append((HEADER_TRUNCATED, b"true"))
        value = b""
    kept = [(k, v) for k, v in headers if not k.startswith("fleetlink.dlq.")]
    return DeadLetter(dlq_topic, key, value, kept + extra, timestamp_ms)
