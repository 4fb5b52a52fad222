"""What record making produces: records encoded for their buffer, and the per-mapping counters."""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import NamedTuple

from fleetlink.edge.mapping import Delivery
from fleetlink.wire import Record, decode_payload, encode_payload


class Outgoing(NamedTuple):
    """One record for the buffer of its delivery class, already encoded as its spool payload."""

    delivery: Delivery
    payload: bytes
    linger_s: float | None = None
    """How long the record may wait for company in a WAN batch (``None``: the stream's default)."""

    @classmethod
    def of(cls, delivery: Delivery, record: Record, linger_s: float | None = None) -> Outgoing:
        """Encode ``record`` as the spool payload for the buffer of ``delivery``."""
        return cls(delivery, encode_payload(record), linger_s)

    @property
    def record(self) -> Record:
        """The record the payload encodes (decoded on demand: for tests and inspection)."""
        return decode_payload(self.payload)


@dataclass(slots=True)
class MappingCounters:
    """Per mapping, in samples (``emitted`` in records)."""

    received: int = 0
    emitted: int = 0
    dropped: int = 0
    """Dropped on purpose by stages (filtered, throttled, unchanged, late) or by a stage error."""
    dead_lettered: int = 0
    type_mismatch: int = 0
    """Samples of another type than the mapping declares (not mapped, not dead-lettered)."""

    def as_dict(self) -> dict[str, int]:
        """The counters by field name."""
        return {f.name: getattr(self, f.name) for f in fields(self)}
