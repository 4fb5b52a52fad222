"""Records and their spool payload encoding, and Avro single-object helpers.

A payload is ``head | value | [source seq] | tail``: the head and the value vary per record, the
tail (topic, key, headers) is usually the same for every record of one robot and mapping. The
edge therefore encodes the tail once (``PayloadTemplate``) and the uplink parses each distinct
tail once per batch (``decode_record``). The ROS sequence number, the one header that changes
with every record, travels as a fixed field (``FLAG_SOURCE_SEQ``) and comes out as the
``fleetlink.seq`` header.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable, Sequence
from typing import NamedTuple

from fleetlink.wire.errors import WireError
from fleetlink.wire.framing import U16, U32, U64, Reader, str16

SINGLE_OBJECT_MAGIC = b"\xc3\x01"
FLAG_RAW_VALUE = 0x01
FLAG_NULL_KEY = 0x02
FLAG_SOURCE_SEQ = 0x04
"""A u64 source sequence number follows the value; decoded as the ``fleetlink.seq`` header."""
RECORD_FLAGS = FLAG_RAW_VALUE | FLAG_NULL_KEY | FLAG_SOURCE_SEQ
"""Every flag a record payload may carry; any other bit is refused."""
SOURCE_SEQ_HEADER = "fleetlink.seq"
_PAYLOAD_HEAD = struct.Struct("<BqI")
VALUE_OFFSET = _PAYLOAD_HEAD.size
"""Where the value starts in a record payload (its fingerprint is at +2 .. +10)."""

Headers = tuple[tuple[str, bytes], ...]


class Record(NamedTuple):
    """One Kafka record to produce. ``key=None`` is a null key; ``raw_value`` values are
    produced as is, others are Avro single-object encoded (``fingerprint`` names the schema).
    (A named tuple: batches of thousands of them are built per second.)"""

    kafka_topic: str
    key: bytes | None
    value: bytes
    headers: Headers = ()
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
    if value[:2] != SINGLE_OBJECT_MAGIC:
        raise WireError(f"not an Avro single-object value (starts {bytes(value[:2]).hex() or 'empty'})")
    if len(value) < 10:
        raise WireError(f"{len(value)} bytes are too short for an Avro single-object header")
    return bytes(value[2:10]), memoryview(value)[10:]


def _tail(kafka_topic: str, key: bytes | None, headers: Sequence[tuple[str, bytes]]) -> bytes:
    key = key or b""
    parts = [str16(kafka_topic), U32.pack(len(key)), key, U16.pack(len(headers))]
    if len(headers) > 0xFFFF:
        raise WireError(f"{len(headers)} headers do not fit a 16-bit count")
    for name, value in headers:
        parts += (str16(name), U32.pack(len(value)), value)
    return b"".join(parts)


def encode_payload(record: Record) -> bytes:
    """A record's spool payload (everything but its seq)."""
    flags = (FLAG_RAW_VALUE if record.raw_value else 0) | (FLAG_NULL_KEY if record.key is None else 0)
    return (
        _PAYLOAD_HEAD.pack(flags, record.timestamp_ms, len(record.value))
        + record.value
        + _tail(record.kafka_topic, record.key, record.headers)
    )


class PayloadTemplate:
    """Payloads that share topic, key and headers, made with one ``struct.pack`` each.

    ``payload(value, timestamp_ms, source_seq)`` equals ``encode_payload`` of the record with
    ``headers + (("fleetlink.seq", str(source_seq)),)`` once decoded.
    """

    __slots__ = ("_flags", "_tail")

    def __init__(
        self, kafka_topic: str, key: bytes | None, headers: Sequence[tuple[str, bytes]] = ()
    ) -> None:
        self._tail = _tail(kafka_topic, key, headers)
        self._flags = FLAG_NULL_KEY if key is None else 0

    @property
    def tail(self) -> bytes:
        """Topic, key and headers as encoded after each payload's value (and source seq)."""
        return self._tail

    @property
    def flags(self) -> int:
        """The record flags every payload of the template carries (besides ``FLAG_SOURCE_SEQ``)."""
        return self._flags

    def payload(self, value: bytes, timestamp_ms: int, source_seq: int | None = None) -> bytes:
        """The payload of one record with ``value``, ``timestamp_ms`` (ms since the epoch) and, when given,
        ``source_seq``."""
        if source_seq is None:
            return _PAYLOAD_HEAD.pack(self._flags, timestamp_ms, len(value)) + value + self._tail
        if not 0 <= source_seq < 1 << 64:
            raise WireError(f"source seq {source_seq} does not fit a u64")
        return (
            _PAYLOAD_HEAD.pack(self._flags | FLAG_SOURCE_SEQ, timestamp_ms, len(value))
            + value
            + U64.pack(source_seq)
            + self._tail
        )


def payload_fingerprint(payload: bytes) -> bytes | None:
    """The schema fingerprint of a payload's value (without decoding it), or ``None``."""
    if len(payload) < VALUE_OFFSET + 10 or payload[0] & FLAG_RAW_VALUE:
        return None
    start = VALUE_OFFSET
    if payload[start : start + 2] != SINGLE_OBJECT_MAGIC:
        return None
    return payload[start + 2 : start + 10]


def payload_fingerprints(payloads: Iterable[bytes]) -> set[bytes]:
    """``{payload_fingerprint(p)}`` of many payloads without ``None`` (one pass, no call each)."""
    head, start, end = VALUE_OFFSET, VALUE_OFFSET + 2, VALUE_OFFSET + 10
    return {
        p[start:end]
        for p in payloads
        if len(p) >= end and not p[0] & FLAG_RAW_VALUE and p[head:start] == SINGLE_OBJECT_MAGIC
    }


def decode_payload(payload: bytes | memoryview, seq: int = 0) -> Record:
    """Inverse of ``encode_payload`` (and of ``PayloadTemplate.payload``); raises ``WireError``."""
    data = bytes(payload)
    return decode_record(data, 0, len(data), seq, tails={})


Tails = dict[bytes, tuple[str, bytes, Headers]]
"""Parsed tails by their bytes: a cache for one batch (``decode_record``)."""


def decode_record(data: bytes, pos: int, end: int, seq: int, *, tails: Tails) -> Record:
    """The record payload ``data[pos:end]``; every failure is a ``WireError`` with the offset.

    ``tails`` remembers each distinct tail already parsed (pass the same dict for the records of
    one batch).
    """
    if end - pos < VALUE_OFFSET:
        raise WireError("truncated record header", offset=pos)
    flags, timestamp_ms, value_len = _PAYLOAD_HEAD.unpack_from(data, pos)
    if flags & ~RECORD_FLAGS:
        raise WireError(f"unknown record flags 0x{flags:02x}", offset=pos)
    start = pos + VALUE_OFFSET
    tail_at = start + value_len
    if tail_at > end:
        raise WireError(f"truncated record value: needs {value_len} bytes, {end - start} left", offset=start)
    value = data[start:tail_at]
    source_seq = -1
    if flags & FLAG_SOURCE_SEQ:
        if tail_at + 8 > end:
            raise WireError("truncated source seq", offset=tail_at)
        (source_seq,) = U64.unpack_from(data, tail_at)
        tail_at += 8
    tail = data[tail_at:end]
    parsed = tails.get(tail)
    if parsed is None:
        parsed = tails[tail] = _parse_tail(data, tail_at, end)
    topic, key, headers = parsed
    if flags & FLAG_NULL_KEY and key:
        raise WireError("record flagged with a null key carries key bytes", offset=tail_at)
    if source_seq >= 0:
        headers = (*headers, (SOURCE_SEQ_HEADER, str(source_seq).encode()))
    return Record(
        topic,
        None if flags & FLAG_NULL_KEY else key,
        value,
        headers,
        timestamp_ms,
        seq,
        bool(flags & FLAG_RAW_VALUE),
    )


def _parse_tail(data: bytes, pos: int, end: int) -> tuple[str, bytes, Headers]:
    r = Reader(data, pos, end)
    topic = r.text("Kafka topic")
    key = r.blob("record key")
    (n_headers,) = r.unpack(U16, "header count")
    headers = tuple((r.text("header name"), r.blob("header value")) for _ in range(n_headers))
    r.done("the record")
    return topic, key, headers
