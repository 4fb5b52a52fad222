"""Acknowledgements: the uplink's answer to one batch."""

from __future__ import annotations

import struct
from dataclasses import dataclass
from typing import Literal

from fleetlink.wire.errors import WireError
from fleetlink.wire.framing import U16, U32, VERSION, Reader, str16

ACK_MAGIC = b"FLA"
_ACK_RANGE = struct.Struct("<QQB")
_FAILURE_HEAD = struct.Struct("<QB")
AckStatus = Literal["ok", "error", "need_schemas", "held_back"]
_STATUS_CODES: dict[str, int] = {"ok": 0, "error": 1, "need_schemas": 2, "held_back": 3}
_STATUS_NAMES: dict[int, AckStatus] = {0: "ok", 1: "error", 2: "need_schemas", 3: "held_back"}


@dataclass(frozen=True, slots=True)
class RecordFailure:
    """A record of a batch that was not produced: its ``seq``, why, and whether it went to the dead-letter
    topic instead (else the edge sends it again)."""

    seq: int
    reason: str
    dead_lettered: bool


@dataclass(frozen=True, slots=True)
class Ack:
    """The uplink's answer to one batch (see the package docstring for the statuses).

    ``need_schemas``: nothing of the batch was produced; the uplink knows no schema text for
    ``missing_schemas``, which the batch left out (``Batch.elided``): send it again with them.

    ``held_back``: nothing of the batch was produced, because an earlier batch of its stream was
    not: send it again after that one.

    ``max_record_bytes``: the largest Kafka record the answering uplink produces (its producer's
    ``message.max.bytes``; 0: not said). The edge applies it before the WAN (docs/images.md).
    """

    edge_id: str
    stream: str
    first_seq: int
    last_seq: int
    status: AckStatus
    failures: tuple[RecordFailure, ...] = ()
    detail: str = ""
    missing_schemas: tuple[bytes, ...] = ()
    max_record_bytes: int = 0

    def __post_init__(self) -> None:
        if self.status not in _STATUS_CODES:
            raise WireError(f"ack status must be one of {', '.join(_STATUS_CODES)}, got {self.status!r}")
        if (self.status == "need_schemas") != bool(self.missing_schemas):
            raise WireError("missing schemas come with status 'need_schemas', and only with it")
        if any(len(fp) != 8 for fp in self.missing_schemas) or len(self.missing_schemas) > 0xFFFF:
            raise WireError("missing schemas are at most 65535 fingerprints of 8 bytes")
        if self.last_seq < self.first_seq:
            raise WireError(f"ack range {self.first_seq}..{self.last_seq} is empty")
        if self.first_seq < 0 or self.last_seq >= 2**64:
            raise WireError(f"ack range {self.first_seq}..{self.last_seq} is not within 0..2^64-1")
        if self.status == "ok" and not all(f.dead_lettered for f in self.failures):
            raise WireError("an 'ok' ack may list only dead-lettered failures")
        if not 0 <= self.max_record_bytes < 2**32:
            raise WireError(f"max_record_bytes {self.max_record_bytes} is not within 0..2^32-1")


def encode_ack(ack: Ack) -> bytes:
    """The wire bytes of ``ack``: magic, version, range and status, detail, failures, missing schemas,
    record limit."""
    parts = [
        ACK_MAGIC,
        bytes([VERSION]),
        str16(ack.edge_id),
        str16(ack.stream),
        _ACK_RANGE.pack(ack.first_seq, ack.last_seq, _STATUS_CODES[ack.status]),
        str16(ack.detail),
        U32.pack(len(ack.failures)),
    ]
    for failure in ack.failures:
        parts += (_FAILURE_HEAD.pack(failure.seq, int(failure.dead_lettered)), str16(failure.reason))
    if ack.status == "need_schemas":
        parts += (U16.pack(len(ack.missing_schemas)), *ack.missing_schemas)
    parts.append(U32.pack(ack.max_record_bytes))
    return b"".join(parts)


def decode_ack(data: bytes) -> Ack:
    """Parse and check an ack; raises ``WireError`` naming what is wrong and where. An ack that ends
    before the record limit reads it as 0 (not said)."""
    r = Reader(data)
    if r.take(3, "ack magic") != ACK_MAGIC:
        raise WireError("not a fleetlink ack", offset=0)
    (version,) = r.take(1, "ack version")
    if version != VERSION:
        raise WireError(f"unsupported ack version {version}", offset=3)
    edge_id, stream = r.text("edge_id"), r.text("stream")
    first_seq, last_seq, status = r.unpack(_ACK_RANGE, "ack range")
    name = _STATUS_NAMES.get(status)
    if name is None:
        raise WireError(f"unknown ack status {status}", offset=r.pos - 1)
    detail = r.text("ack detail")
    (n_failures,) = r.unpack(U32, "failure count")
    failures = []
    for _ in range(n_failures):
        seq, dead = r.unpack(_FAILURE_HEAD, "failure")
        if dead > 1:
            raise WireError(f"bad dead_lettered flag {dead}", offset=r.pos - 1)
        failures.append(RecordFailure(seq=seq, dead_lettered=bool(dead), reason=r.text("failure reason")))
    missing: tuple[bytes, ...] = ()
    if name == "need_schemas":
        (n_missing,) = r.unpack(U16, "missing schema count")
        missing = tuple(r.take(8, "missing schema fingerprint") for _ in range(n_missing))
    # an uplink from before the limit was told ends here: 0, "not said"
    (max_record_bytes,) = r.unpack(U32, "max record bytes") if r.end > r.pos else (0,)
    r.done("the ack")
    return Ack(
        edge_id=edge_id,
        stream=stream,
        first_seq=first_seq,
        last_seq=last_seq,
        status=name,
        failures=tuple(failures),
        detail=detail,
        missing_schemas=missing,
        max_record_bytes=max_record_bytes,
    )
