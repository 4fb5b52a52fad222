"""Avro framings: single-object encoding (spec) and the Confluent wire format.

Single-object encoding = ``C3 01`` + the 8-byte little-endian CRC-64-AVRO fingerprint of the
schema's Parsing Canonical Form + the Avro body; records travel without a registry and any
reader that knows the schema set can resolve them. Confluent wire format = ``00`` + 4-byte
big-endian schema id + the body. The uplink swaps one for the other without touching the body.
"""

from __future__ import annotations

import json
import struct
from typing import Any

from fastavro.schema import to_parsing_canonical_form

from fleetlink.schemas.errors import DecodeError

MARKER = b"\xc3\x01"
CONFLUENT_MAGIC = 0
_EMPTY = 0xC15D213AA4D7A795  # the CRC-64-AVRO seed ("empty" fingerprint), from the Avro spec


def _table() -> tuple[int, ...]:
    table = []
    for i in range(256):
        fp = i
        for _ in range(8):
            fp = (fp >> 1) ^ (_EMPTY & -(fp & 1))
        table.append(fp)
    return tuple(table)


_TABLE = _table()


class FramingError(DecodeError):
    """Bytes that do not carry the expected framing header."""

    def __init__(self, framing: str, offset: int, reason: str, data: bytes) -> None:
        super().__init__(framing, offset, reason, data)


def crc64_avro(data: bytes) -> int:
    """The Rabin CRC-64 the Avro spec calls CRC-64-AVRO."""
    fp = _EMPTY
    for byte in data:
        fp = (fp >> 8) ^ _TABLE[(fp ^ byte) & 0xFF]
    return fp


def canonical_form(schema: dict[str, Any] | str) -> str:
    """Parsing Canonical Form of a schema (dict, or its JSON text)."""
    parsed = json.loads(schema) if isinstance(schema, str) else schema
    text: str = to_parsing_canonical_form(parsed)
    return text


def fingerprint(schema: dict[str, Any] | str) -> bytes:
    """8-byte little-endian CRC-64-AVRO fingerprint of the schema's Parsing Canonical Form."""
    return struct.pack("<Q", crc64_avro(canonical_form(schema).encode()))


def frame(fp: bytes, body: bytes) -> bytes:
    """A single-object encoded record."""
    if len(fp) != 8:
        raise FramingError("single-object", 0, f"a fingerprint has 8 bytes, got {len(fp)}", fp)
    return MARKER + fp + body


def unframe(data: bytes) -> tuple[bytes, bytes]:
    """(fingerprint, body) of a single-object encoded record."""
    if len(data) < 10:
        raise FramingError(
            "single-object", len(data), f"{len(data)} bytes are too short for the header", data
        )
    if data[:2] != MARKER:
        raise FramingError("single-object", 0, f"marker {data[:2].hex(' ')} is not c3 01", data)
    return data[2:10], data[10:]


def confluent_frame(schema_id: int, body: bytes) -> bytes:
    """A record in the Confluent wire format."""
    if not 0 <= schema_id <= 0xFFFF_FFFF:
        raise FramingError("confluent", 0, f"schema id {schema_id} does not fit 4 bytes", body)
    return struct.pack(">bI", CONFLUENT_MAGIC, schema_id) + body


def confluent_unframe(data: bytes) -> tuple[int, bytes]:
    """(schema id, body) of a record in the Confluent wire format."""
    if len(data) < 5:
        raise FramingError("confluent", len(data), f"{len(data)} bytes are too short for the header", data)
    if data[0] != CONFLUENT_MAGIC:
        raise FramingError("confluent", 0, f"magic byte 0x{data[0]:02x} is not 0x00", data)
    schema_id: int = struct.unpack_from(">I", data, 1)[0]
    return schema_id, data[5:]
