"""Records and their spool payload encoding, and Avro single-object helpers."""

from __future__ import annotations

import struct
from dataclasses import dataclass

from fleetlink.wan.errors import WireError
from fleetlink.wan.framing import U16, U32, Reader, str16

SINGLE_OBJECT_MAGIC = b"\xc3\x01"
FLAG_RAW_VALUE = 0x01
FLAG_NULL_KEY = 0x02
_PAYLOAD_HEAD = struct.Struct("<BqI")
VALUE_OFFSET = _PAYLOAD_HEAD.size
"""Where the value starts in a record payload (its fingerprint is at +2 .. +10)."""


@dataclass(frozen=True, slots=True)
class Record:
    """One Kafka record to produce. ``key=None`` is a null key; ``raw_value`` values are
    produced as is, others are Avro single-object encoded (``fingerprint`` names the schema)."""

    kafka_topic: str
    key: bytes | None
    value: bytes
    headers: tuple[tuple[str, bytes], ...] = ()
    timestamp_ms: int = 0
    seq: int = 0
    raw_value: bool = False

    @property
    def fingerprint(self) -> bytes | None:
        """The schema fingerprint of an Avro single-object value, else ``None``."""
        if self.raw_value or len(self.value) < 10 or self.value[:2] != SINGLE_OBJECT_MAGIC:
            return None
        return self.value[2:10]


def single_object(fingerprint: bytes, body: bytes) -> bytes:
    """Avro single-object encoding: ``C3 01`` + 8-byte fingerprint + Avro binary body."""
    if len(fingerprint) != 8:
        raise WireError(f"a schema fingerprint has 8 bytes, got {len(fingerprint)}")
    return SINGLE_OBJECT_MAGIC + fingerprint + body


def split_single_object(value: bytes) -> tuple[bytes, memoryview]:
    """``(fingerprint, body)`` of a single-object encoded value; raises ``WireError``."""
    if len(value) < 10 or value[:2] != SINGLE_OBJECT_MAGIC:
        raise WireError(f"not an Avro single-object value (starts {bytes(value[:2]).hex() or 'empty'})")
    return bytes(value[2:10]), memoryview(value)[10:]


def encode_payload(record: Record) -> bytes:
    """A record's spool payload (everything but its seq)."""
    flags = (FLAG_RAW_VALUE if record.raw_value else 0) | (FLAG_NULL_KEY if record.key is None else 0)
    key = record.key or b""
    parts = [_PAYLOAD_HEAD.pack(flags, record.timestamp_ms, len(record.value)), record.value,
             str16(record.kafka_topic), U32.pack(len(key)), key, U16.pack(len(record.headers))]
    for name, value in record.headers:
        parts += (str16(name), U32.pack(len(value)), value)
    return b"".join(parts)


def payload_fingerprint(payload: bytes) -> bytes | None:
    """The schema fingerprint of a payload's value (without decoding it), or ``None``."""
    if len(payload) < VALUE_OFFSET + 10 or payload[0] & FLAG_RAW_VALUE:
        return None
    start = VALUE_OFFSET
    if payload[start : start + 2] != SINGLE_OBJECT_MAGIC:
        return None
    return payload[start + 2 : start + 10]


def decode_payload(payload: bytes | memoryview, seq: int = 0) -> Record:
    """Inverse of ``encode_payload``; raises ``WireError``."""
    return decode_payload_from(Reader(payload), seq)


def decode_payload_from(r: Reader, seq: int) -> Record:
    flags, timestamp_ms, value_len = r.unpack(_PAYLOAD_HEAD, "record header")
    if flags & ~(FLAG_RAW_VALUE | FLAG_NULL_KEY):
        raise WireError(f"unknown record flags 0x{flags:02x}", offset=r.pos - _PAYLOAD_HEAD.size)
    value = r.take(value_len, "record value")
    topic = r.text("Kafka topic")
    key = r.blob("record key")
    if flags & FLAG_NULL_KEY and key:
        raise WireError("record flagged with a null key carries key bytes", offset=r.pos)
    (n_headers,) = r.unpack(U16, "header count")
    headers = tuple((r.text("header name"), r.blob("header value")) for _ in range(n_headers))
    r.done("the record")
    return Record(kafka_topic=topic, key=None if flags & FLAG_NULL_KEY else key, value=value,
                  headers=headers, timestamp_ms=timestamp_ms, seq=seq, raw_value=bool(flags & FLAG_RAW_VALUE))

