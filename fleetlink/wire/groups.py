"""Record groups: consecutive records of one stream as one unit, on disk and on the WAN (pure).

The edge spools, reads back and sends records a group at a time, so that its cost is per group,
not per record; the uplink unpacks the records. A group's payload (little-endian)::

    count u32 | n_fingerprints u16 | { fingerprint 8 bytes } * n | { length u32 | record payload } * count

``count`` records with consecutive seqs (the first is carried beside the group: in the spool's
frame header, in the batch); the fingerprints are the schemas their Avro values use (so the
sender knows which schema texts a batch needs without reading each record); a record payload is
``fleetlink.wire.records``' encoding.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator, Sequence

from fleetlink.wire.errors import WireError
from fleetlink.wire.records import payload_fingerprints

_HEAD = struct.Struct("<IH")
HEAD_SIZE = _HEAD.size
_LEN = struct.Struct("<I")


def encode_group(payloads: Sequence[bytes]) -> bytes:
    """The group of ``payloads`` (at least one), its fingerprints read from the payloads."""
    if not payloads:
        raise WireError("a group needs at least one record")
    fingerprints = sorted(payload_fingerprints(payloads))
    if len(fingerprints) > 0xFFFF:
        raise WireError(f"{len(fingerprints)} schemas do not fit a group")
    parts = [_HEAD.pack(len(payloads), len(fingerprints)), *fingerprints]
    pack = _LEN.pack
    for payload in payloads:
        parts += (pack(len(payload)), payload)
    return b"".join(parts)


def group_head(group: bytes | memoryview) -> tuple[int, tuple[bytes, ...], int]:
    """``(count, fingerprints, offset of the first record)``; raises ``WireError``."""
    count, start = _count_and_start(group)
    at = range(HEAD_SIZE, start, 8)
    if isinstance(group, bytes):
        return count, tuple([group[i : i + 8] for i in at]), start
    return count, tuple([bytes(group[i : i + 8]) for i in at]), start


def _count_and_start(group: bytes | memoryview) -> tuple[int, int]:
    """``(count, offset of the first record)``; raises ``WireError``."""
    if len(group) < HEAD_SIZE:
        raise WireError(f"a group has at least {HEAD_SIZE} bytes, got {len(group)}")
    count, n_fps = _HEAD.unpack_from(group, 0)
    start = HEAD_SIZE + 8 * n_fps
    if count < 1:
        raise WireError("a group holds at least one record")
    if start > len(group):
        raise WireError(f"group of {len(group)} bytes is too short for {n_fps} fingerprints")
    return count, start


def group_count(group: bytes | memoryview) -> int:
    """How many records a group holds (unchecked beyond its header)."""
    if len(group) < HEAD_SIZE:
        raise WireError(f"a group has at least {HEAD_SIZE} bytes, got {len(group)}")
    count: int = _LEN.unpack_from(group, 0)[0]
    return count


def record_spans(data: bytes | memoryview, pos: int, end: int, count: int) -> Iterator[tuple[int, int]]:
    """``(start, end)`` of each of ``count`` length-prefixed record payloads in ``data[pos:end]``."""
    unpack = _LEN.unpack_from
    for n in range(count):
        if end - pos < 4:
            raise WireError(f"group truncated before record {n + 1} of {count}", offset=pos)
        (length,) = unpack(data, pos)
        pos += 4
        if length > end - pos:
            raise WireError(f"record {n + 1} of {count} runs past its group", offset=pos)
        yield pos, pos + length
        pos += length
    if pos != end:
        raise WireError(f"{end - pos} bytes after the {count} records of a group", offset=pos)


def group_payloads(group: bytes) -> list[bytes]:
    """The record payloads of a group (for inspection and tests)."""
    count, _fps, start = group_head(group)
    return [group[a:b] for a, b in record_spans(group, start, len(group), count)]


def split_group(group: bytes, max_records: int, max_bytes: int) -> list[bytes]:
    """``group`` as groups of at most ``max_records`` records and, beyond one record each,
    ``max_bytes`` of payload (a group that fits is returned as it is)."""
    count, start = _count_and_start(group)
    if count <= max_records and len(group) - start <= max_bytes:
        return [group]
    out: list[bytes] = []
    chunk: list[bytes] = []
    size = 0
    for a, b in record_spans(group, start, len(group), count):
        if chunk and (len(chunk) >= max_records or size + (b - a) + 4 > max_bytes):
            out.append(encode_group(chunk))
            chunk, size = [], 0
        chunk.append(group[a:b])
        size += (b - a) + 4
    out.append(encode_group(chunk))
    return out
