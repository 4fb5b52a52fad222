"""Batches: encode (from records, or straight from spool payloads) and decode, compressed."""

from __future__ import annotations

import dataclasses
import struct
import zlib
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Literal

from fleetlink.wire.errors import WireError
from fleetlink.wire.framing import U16, U32, U64, Reader, str16
from fleetlink.wire.groups import encode_group, group_count, group_head, record_spans
from fleetlink.wire.records import Record, Tails, decode_record, encode_payload

try:  # zstd is in the standard library from Python 3.14; the backport is a rosbags dependency
    from compression import zstd as _zstd  # type: ignore[import-not-found,unused-ignore]
except ImportError:  # pragma: no cover - depends on the Python version
    try:
        from backports import zstd as _zstd  # type: ignore[no-redef,unused-ignore]
    except ImportError:
        _zstd = None

_DECOMPRESS_ERRORS: tuple[type[Exception], ...] = (zlib.error, EOFError) + (
    () if _zstd is None else (_zstd.ZstdError,)
)

Codec = Literal["none", "zlib", "zstd"]
_CODECS: dict[str, int] = {"none": 0, "zlib": 1, "zstd": 2}
_CODEC_NAMES = {v: k for k, v in _CODECS.items()}

BATCH_MAGIC = b"FLB"
BATCH_VERSION = 6
"""The only version written and read (6 added ``acked`` to the head; others are refused)."""
_ELIDED = 0xFFFFFFFF
"""A schema entry's length that says "text left out" (``Batch.elided``)."""
MAX_BATCH_BYTES = 64 * 1024 * 1024
"""Default cap on a batch's uncompressed body (a decompression-bomb guard)."""
_ELIDED_BYTES = U32.pack(_ELIDED)
_HEAD = struct.Struct("<3sBBI")
_SEQ_LEN = struct.Struct("<QI")


def zstd_available() -> bool:
    """Whether this Python can compress and decompress with the ``zstd`` codec."""
    return _zstd is not None


@dataclass(frozen=True, slots=True)
class Batch:
    """Records from one edge stream, ``seq`` strictly increasing from ``first_seq``, with the
    schema JSON of the fingerprints they use (``schemas``: fingerprint -> JSON text). ``elided``
    are fingerprints they use whose text the edge left out, because an uplink acknowledged a
    batch carrying it before (an uplink that does not know one answers ``need_schemas``)."""

    site: str
    edge_id: str
    stream: str
    first_seq: int
    records: tuple[Record, ...]
    schemas: Mapping[bytes, str] = field(default_factory=dict)
    elided: frozenset[bytes] = frozenset()
    origin: int = 0
    """Non-zero: the stream is delivered exactly once, and this is its origin, the random id of
    the spool its seqs come from (a new spool starts its seqs again under a new origin). Zero:
    at-least-once."""
    acked: int = 0
    """The edge's ack mark when it sent the batch: every record of the stream at or below this seq
    was acknowledged or dropped and will not be sent again (below ``first_seq``). An exactly-once
    uplink writes a batch only when no record the edge may still send lies between the stream's
    mark and the batch (docs/exactly-once.md)."""

    @property
    def last_seq(self) -> int:
        """The seq of the last record (``first_seq`` when the batch has none)."""
        return self.records[-1].seq if self.records else self.first_seq


def _compress(body: bytes, codec: Codec, level: int | None) -> bytes:
    if codec == "none":
        return body
    if codec == "zlib":
        return zlib.compress(body, 1 if level is None else level)
    if _zstd is None:
        raise WireError("the zstd codec is not available in this Python")
    return bytes(_zstd.compress(body, 1 if level is None else level))


def encode_batch_groups(
    *,
    site: str,
    edge_id: str,
    stream: str,
    groups: Sequence[tuple[int, bytes]],
    schemas: Mapping[bytes, str],
    elided: Collection[bytes] = (),
    codec: Codec = "zlib",
    level: int | None = None,
    origin: int = 0,
    acked: int = 0,
) -> bytes:
    """A batch from record groups ``(first_seq, group)`` as the spool keeps them (no per-record
    work); ``elided``: fingerprints used without their text; ``origin``, ``acked``: see ``Batch``."""
    if not groups:
        raise WireError("a batch needs at least one record")
    if codec not in _CODECS:
        raise WireError(f"unknown codec {codec!r}")
    if len(schemas) + len(elided) > 0xFFFF:
        raise WireError(f"{len(schemas) + len(elided)} schemas do not fit a 16-bit count")
    if not 0 <= origin < 1 << 64:
        raise WireError(f"origin {origin} does not fit a u64")
    _check_acked(acked, groups[0][0])
    parts = [
        str16(site),
        str16(edge_id),
        str16(stream),
        U64.pack(origin),
        U64.pack(groups[0][0]),
        U64.pack(acked),
        U16.pack(len(schemas) + len(elided)),
    ]
    for fingerprint in elided:
        if len(fingerprint) != 8:
            raise WireError(f"a schema fingerprint has 8 bytes, got {len(fingerprint)}")
        if fingerprint in schemas:
            raise WireError(f"schema {fingerprint.hex()} is both carried and elided")
        parts += (fingerprint, U32.pack(_ELIDED))
    for fingerprint, schema in schemas.items():
        if len(fingerprint) != 8:
            raise WireError(f"a schema fingerprint has 8 bytes, got {len(fingerprint)}")
        data = schema.encode("utf-8")
        if len(data) >= _ELIDED:
            raise WireError(f"schema {fingerprint.hex()} of {len(data)} bytes is too long")
        parts += (fingerprint, U32.pack(len(data)), data)
    parts.append(U32.pack(len(groups)))
    following = 0
    for first_seq, group in groups:
        if first_seq < following:
            raise WireError(f"record seqs must increase: a group starts at {first_seq}, below {following}")
        following = first_seq + group_count(group)
        parts += (_SEQ_LEN.pack(first_seq, len(group)), group)
    body = b"".join(parts)
    return _HEAD.pack(BATCH_MAGIC, BATCH_VERSION, _CODECS[codec], len(body)) + _compress(body, codec, level)


def encode_batch_payloads(
    *,
    site: str,
    edge_id: str,
    stream: str,
    items: Sequence[tuple[int, bytes]],
    schemas: Mapping[bytes, str],
    elided: Collection[bytes] = (),
    codec: Codec = "zlib",
    level: int | None = None,
    origin: int = 0,
    acked: int = 0,
) -> bytes:
    """A batch from record payloads ``(seq, payload)``: runs of consecutive seqs become groups."""
    groups: list[tuple[int, bytes]] = []
    run: list[bytes] = []
    first = previous = -1
    for seq, payload in items:
        if seq <= previous:
            raise WireError(f"record seqs must increase: {seq} after {previous}")
        if run and seq != previous + 1:
            groups.append((first, encode_group(run)))
            run = []
        if not run:
            first = seq
        run.append(payload)
        previous = seq
    if run:
        groups.append((first, encode_group(run)))
    return encode_batch_groups(
        site=site,
        edge_id=edge_id,
        stream=stream,
        groups=groups,
        schemas=schemas,
        elided=elided,
        codec=codec,
        level=level,
        origin=origin,
        acked=acked,
    )


def encode_batch(batch: Batch, *, codec: Codec = "zlib", level: int | None = None) -> bytes:
    """Encode ``batch``; every record's ``seq`` is used, ``first_seq`` must equal the first one's."""
    if batch.records and batch.records[0].seq != batch.first_seq:
        raise WireError(f"first_seq {batch.first_seq} is not the first record's seq {batch.records[0].seq}")
    return encode_batch_payloads(
        site=batch.site,
        edge_id=batch.edge_id,
        stream=batch.stream,
        items=[(r.seq, encode_payload(r)) for r in batch.records],
        schemas=batch.schemas,
        elided=batch.elided,
        codec=codec,
        level=level,
        origin=batch.origin,
        acked=batch.acked,
    )


def _check_acked(acked: int, first_seq: int) -> None:
    if not 0 <= acked < max(first_seq, 1):
        raise WireError(f"acked {acked} must be below the first seq {first_seq} (and not negative)")


def _decompress(codec: int, data: memoryview, limit: int) -> bytes:
    """The body, at most ``limit`` bytes of it."""
    if codec == 0:
        return bytes(data[:limit])
    try:
        if codec == 1:
            out = zlib.decompressobj().decompress(data, limit)
        elif codec == 2:
            if _zstd is None:
                raise WireError("batch compressed with zstd, which this Python lacks")
            out = _zstd.ZstdDecompressor().decompress(data, limit)
        else:
            raise WireError(f"unknown codec {codec}", offset=4)
    except _DECOMPRESS_ERRORS as exc:
        raise WireError(f"corrupt {_CODEC_NAMES[codec]} data: {exc}") from None
    return bytes(out)


def _read_schemas(r: Reader) -> tuple[dict[bytes, str], frozenset[bytes]]:
    """The schema section: texts by fingerprint, and the fingerprints left out."""
    (n_schemas,) = r.unpack(U16, "schema count")
    schemas: dict[bytes, str] = {}
    elided: set[bytes] = set()
    for _ in range(n_schemas):
        fingerprint = r.take(8, "schema fingerprint")
        if fingerprint in schemas or fingerprint in elided:
            raise WireError(f"schema {fingerprint.hex()} is listed twice", offset=r.pos - 8)
        if r.data[r.pos : r.pos + 4] == _ELIDED_BYTES:
            r.pos += 4
            elided.add(fingerprint)
        else:
            schemas[fingerprint] = r.text("schema JSON", wide=True)
    return schemas, frozenset(elided)


def _read_group(
    body: bytes, pos: int, end: int, following: int, *, records: list[Record], tails: Tails
) -> tuple[int, int]:
    """Decode the group at ``pos`` into ``records``; returns where the next group starts and the
    seq after its last record."""
    if end - pos < _SEQ_LEN.size:
        raise WireError("truncated group seq/length", offset=pos)
    seq, length = _SEQ_LEN.unpack_from(body, pos)
    if seq < following:
        raise WireError(f"record seqs must increase: a group starts at {seq}, below {following}", offset=pos)
    pos += _SEQ_LEN.size
    if length > end - pos:
        raise WireError(f"truncated group at seq {seq}", offset=pos)
    append = records.append
    try:
        count, _fps, start = group_head(memoryview(body)[pos : pos + length])
        for a, b in record_spans(body, pos + start, pos + length, count):
            append(decode_record(body, a, b, seq, tails=tails))
            seq += 1
    except WireError as exc:
        raise WireError(f"group at byte {pos}: {exc.reason}", offset=exc.offset) from None
    return pos + length, seq


@dataclass(frozen=True, slots=True)
class BatchBody:
    """A batch decompressed, its header and schemas read: ``head`` without records, the body,
    and where its groups start (what the uplink's native path parses on its own)."""

    head: Batch
    body: bytes
    groups_at: int


PEEK_BYTES = 4096
"""How much of a batch's body ``peek_stream`` decompresses at most."""
PEEK_INPUT_BYTES = 65536
"""How much of a compressed batch ``peek_stream`` hands the decompressor at most (it would copy
the rest of a large batch as unread input)."""


@dataclass(frozen=True, slots=True)
class StreamHead:
    """Whose stream a batch belongs to and where it starts (``peek_stream``)."""

    site: str
    edge_id: str
    stream: str
    origin: int
    first_seq: int


def peek_stream(data: bytes, *, max_bytes: int = MAX_BATCH_BYTES) -> StreamHead | None:
    """The site, edge, stream, origin and first seq of a batch, from its start only (at most
    ``PEEK_INPUT_BYTES`` read, ``PEEK_BYTES`` decompressed): what an uplink that will not read a
    batch needs to keep its stream's order. ``None`` when the batch is not well formed that far,
    or is one that ``decode_batch_head`` refuses from what is read."""
    view = memoryview(data)
    if len(view) < _HEAD.size:
        return None
    magic, version, codec, size = _HEAD.unpack_from(view, 0)
    if magic != BATCH_MAGIC or version != BATCH_VERSION or not 0 < size <= max_bytes:
        return None
    try:
        start = _decompress(codec, view[_HEAD.size : _HEAD.size + PEEK_INPUT_BYTES], min(size, PEEK_BYTES))
        r = Reader(start)
        site, edge_id, stream = r.text("site"), r.text("edge_id"), r.text("stream")
        origin, first_seq, acked = (r.unpack(U64, what)[0] for what in ("origin", "first_seq", "acked"))
        _check_acked(acked, first_seq)
    except WireError:
        return None
    return StreamHead(site, edge_id, stream, origin, first_seq)


def decode_batch_head(data: bytes, *, max_bytes: int = MAX_BATCH_BYTES) -> BatchBody:
    """Check the framing, decompress, read site, edge, stream, first seq and schemas."""
    view = memoryview(data)
    if len(view) < _HEAD.size:
        raise WireError(f"a batch has at least {_HEAD.size} bytes, got {len(view)}", offset=0)
    magic, version, codec, size = _HEAD.unpack_from(view, 0)
    if magic != BATCH_MAGIC:
        raise WireError(f"not a fleetlink batch (magic {bytes(magic).hex()})", offset=0)
    if version != BATCH_VERSION:
        raise WireError(f"unsupported batch version {version}", offset=3)
    if size > max_bytes:
        raise WireError(f"batch body of {size} bytes exceeds the {max_bytes}-byte limit", offset=5)
    body = _decompress(codec, view[_HEAD.size :], size + 1)
    if len(body) != size:
        raise WireError(f"batch body has {len(body)} bytes, header says {size}")
    r = Reader(body)
    site, edge_id, stream = r.text("site"), r.text("edge_id"), r.text("stream")
    (origin,) = r.unpack(U64, "origin")
    (first_seq,) = r.unpack(U64, "first_seq")
    (acked,) = r.unpack(U64, "acked")
    _check_acked(acked, first_seq)
    schemas, elided = _read_schemas(r)
    head = Batch(
        site=site,
        edge_id=edge_id,
        stream=stream,
        first_seq=first_seq,
        records=(),
        schemas=schemas,
        elided=elided,
        origin=origin,
        acked=acked,
    )
    return BatchBody(head, body, r.pos)


def decode_batch(data: bytes, *, max_bytes: int = MAX_BATCH_BYTES) -> Batch:
    """Parse and check a batch; raises ``WireError`` naming what is wrong and where."""
    parsed = decode_batch_head(data, max_bytes=max_bytes)
    head, body = parsed.head, parsed.body
    first_seq = head.first_seq
    r = Reader(body, parsed.groups_at)
    (n_groups,) = r.unpack(U32, "group count")
    if n_groups == 0:
        raise WireError("a batch needs at least one record", offset=r.pos - 4)
    records: list[Record] = []
    tails: Tails = {}
    pos, following = r.pos, 0
    for _ in range(n_groups):
        pos, following = _read_group(body, pos, r.end, following, records=records, tails=tails)
    r.pos = pos
    r.done("the batch")
    if records[0].seq != first_seq:
        raise WireError(f"first_seq {first_seq} is not the first record's seq {records[0].seq}")
    return dataclasses.replace(head, records=tuple(records))
