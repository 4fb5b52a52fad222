"""Dead-letter records: what could not be delivered, with its raw bytes and the reason.

Every dead-letter record keeps the original key and headers, carries the raw bytes as its
value (or, when the value itself is too large for Kafka, a SHA-256 reference and the size),
and says in headers which stage refused it, why, and where it was going.
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass

from fleetlink.wire import headers as h
from fleetlink.wire.robot_events import IDENTITY_HEADERS


@dataclass(frozen=True, slots=True)
class DeadLetter:
    """A record the uplink writes in place of one it could not deliver as it was: where to, key, value,
    headers, timestamp."""

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
        (h.DLQ_STAGE, stage.encode()),
        (h.DLQ_REASON, reason.encode("utf-8", "replace")[:2000]),
        (h.DLQ_TOPIC, intended_topic.encode("utf-8", "replace")),
        (h.DLQ_SIZE, str(len(raw)).encode()),
    ]
    value = raw
    if len(raw) > max_value_bytes:
        extra.append((h.DLQ_SHA256, hashlib.sha256(raw).hexdigest().encode()))
        extra.append((h.DLQ_TRUNCATED, b"true"))
        value = b""
    kept = [(k, v) for k, v in headers if not k.startswith(h.DLQ_PREFIX)]
    return DeadLetter(dlq_topic, key, value, kept + extra, timestamp_ms)


def edge_dead_letter_problem(headers: Sequence[tuple[str, bytes]]) -> str | None:
    """Why a record a site sends to the dead-letter topic is not a dead letter its edge made
    (None: it is one). An edge's dead letter says its stage and reason and carries only the
    headers an edge writes, each of bounded size; the uplink sets the sender headers itself."""
    names = {name for name, _value in headers}
    for name, value in headers:
        if name not in h.EDGE_DEAD_LETTER:
            return f"header {name[:100]!r} is not one an edge's dead letter carries"
        if len(value) > h.MAX_HEADER_VALUE:
            return f"header {name} holds {len(value)} bytes (at most {h.MAX_HEADER_VALUE})"
    for needed in (h.DLQ_STAGE, h.DLQ_REASON):
        if needed not in names:
            return f"no {needed} header: not a dead letter"
    return None


def stamped(headers: Sequence[tuple[str, bytes]], site: str, edge_id: str) -> list[tuple[str, bytes]]:
    """``headers`` with the sender headers replaced by the site and edge the batch's key proved."""
    kept = [(name, value) for name, value in headers if name not in IDENTITY_HEADERS]
    return [*kept, (h.SITE_HEADER, site.encode()), (h.EDGE_HEADER, edge_id.encode())]
