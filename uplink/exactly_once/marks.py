"""High-water marks of exactly-once streams: what they are, how they are stored (pure)."""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, replace

from fleetlink.wire import Batch


@dataclass(frozen=True, slots=True)
class MarkKey:
    """One exactly-once stream: an edge's spool, whatever its origin."""

    site: str
    edge_id: str
    stream: str

    def kafka_key(self) -> bytes:
        """The key of the stream's marks in the marks topic (compacted: the last one stays)."""
        return f"{self.site}/{self.edge_id}/{self.stream}".encode()

    def transactional_id(self, prefix: str) -> str:
        """The ``transactional.id`` of the stream's producer: one per stream, fleet-wide."""
        return f"{prefix}.{self.site}.{self.edge_id}.{self.stream}"

    @classmethod
    def of(cls, batch: Batch) -> MarkKey:
        """The stream a batch belongs to."""
        return cls(batch.site, batch.edge_id, batch.stream)


@dataclass(frozen=True, slots=True)
class Mark:
    """Every seq up to ``seq`` of the spool ``origin`` is in Kafka (committed)."""

    origin: int
    seq: int


NO_MARK = Mark(0, 0)


def encode_mark(mark: Mark) -> bytes:
    """The marks topic's value: JSON, the origin in hex (a 64-bit id is not a JSON-safe number)."""
    return json.dumps({"origin": f"{mark.origin:016x}", "seq": mark.seq}, separators=(",", ":")).encode()


def decode_mark(value: bytes) -> Mark | None:
    """The mark a marks-topic value holds (None: not one fleetlink wrote)."""
    try:
        data = json.loads(value)
        return Mark(int(data["origin"], 16), int(data["seq"]))
    except (ValueError, KeyError, TypeError):
        return None


def above(batch: Batch, seq: int) -> Batch:
    """``batch`` with only its records whose seq is above ``seq`` (what Kafka does not have yet
    when ``seq`` is the stream's mark; 0: all of them)."""
    records = tuple(r for r in batch.records if r.seq > seq)
    return replace(batch, records=records, first_seq=records[0].seq if records else batch.first_seq)


def at_or_below(batch: Batch) -> Callable[[int], int]:
    """How many records of ``batch`` have a seq at or below a given one."""
    return lambda seq: sum(1 for r in batch.records if r.seq <= seq)
