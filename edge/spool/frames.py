"""The spool's on-disk framing (pure: bytes in, frames out).

A segment file is a 16-byte header (``FLSPOOL1`` + first seq, u64 LE) then frames::

    magic u16 (0x5BF1) | flags u16 | length u32 | seq u64 | append time ms i64 | crc u32 | payload

all little-endian. With flag bit 0 (``FLAG_GROUP``, what the spool writes) the payload is a record
group (``fleetlink.wire.groups``: ``count`` records with seqs ``seq .. seq + count - 1``); without
it, one record payload with seq ``seq`` (read, never written). With flag bit 1 (``FLAG_MARKS``,
only beside ``FLAG_GROUP``) a marks block (``edge.spool.marks``: the last sequence number of each
publisher whose samples the write held) follows the group.

``crc`` is CRC-32 (zlib's, the IEEE polynomial: C-fast everywhere; CRC-32C would need an extra
package) over the payload followed by the 24 header bytes before it, so
any flipped bit in the length, seq, time or payload is caught. A frame that fails is damage:
the scanner looks for the next magic whose frame checks out and resumes there.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Iterator
from dataclasses import dataclass

from fleetlink.edge.spool.marks import MarksError, marks_block_size
from fleetlink.wire.groups import HEAD_SIZE as GROUP_HEAD_SIZE
from fleetlink.wire.groups import encode_group, group_count

FRAME_MAGIC = 0x5BF1
FLAG_GROUP = 0x0001
FLAG_MARKS = 0x0002
KNOWN_FLAGS = FLAG_GROUP | FLAG_MARKS
MAGIC_BYTES = struct.pack("<H", FRAME_MAGIC)
_PREFIX = struct.Struct("<HHIQq")
_FRAME = struct.Struct("<HHIQqI")
FRAME_HEADER = _FRAME
HEADER_SIZE = _FRAME.size  # 28
SEGMENT_MAGIC = b"FLSPOOL1"
_SEGMENT_HEAD = struct.Struct("<8sQ")
SEGMENT_HEADER_SIZE = _SEGMENT_HEAD.size  # 16


def encode_frame(
    seq: int, timestamp_ms: int, payload: bytes, payload_crc: int | None = None, *, flags: int = 0
) -> bytes:
    """One frame; pass ``payload_crc = zlib.crc32(payload)`` if already computed."""
    prefix = _PREFIX.pack(FRAME_MAGIC, flags, len(payload), seq, timestamp_ms)
    crc = zlib.crc32(prefix, zlib.crc32(payload) if payload_crc is None else payload_crc)
    return prefix + crc.to_bytes(4, "little") + payload


def encode_segment_header(first_seq: int) -> bytes:
    """The 16-byte header of a segment whose first record has seq ``first_seq``."""
    return _SEGMENT_HEAD.pack(SEGMENT_MAGIC, first_seq)


def decode_segment_header(data: bytes) -> int | None:
    """The first seq in a segment header, or ``None`` when the header is not one."""
    if len(data) < SEGMENT_HEADER_SIZE:
        return None
    magic, first_seq = _SEGMENT_HEAD.unpack_from(data, 0)
    return int(first_seq) if magic == SEGMENT_MAGIC else None


def peek_timestamp(header: bytes) -> int | None:
    """The append time in a frame header (unchecked: for statistics only)."""
    if len(header) < HEADER_SIZE:
        return None
    magic, _, _, _, ts, _ = _FRAME.unpack_from(header, 0)
    return int(ts) if magic == FRAME_MAGIC else None


def encode_group_frame(first_seq: int, timestamp_ms: int, group: bytes, marks: bytes = b"") -> bytes:
    """The frame of a record group whose first record has seq ``first_seq``, with a marks block
    (``edge.spool.marks.encode_marks``) when ``marks`` is given."""
    if marks:
        return encode_frame(first_seq, timestamp_ms, group + marks, flags=FLAG_GROUP | FLAG_MARKS)
    return encode_frame(first_seq, timestamp_ms, group, flags=FLAG_GROUP)


def group_end(frame: bytes) -> int:
    """Where the group ends in a frame this spool wrote (before any marks block)."""
    flags = int.from_bytes(frame[2:4], "little")
    if flags & FLAG_MARKS:
        return len(frame) - marks_block_size(frame)
    return len(frame)


@dataclass(frozen=True, slots=True)
class Frame:
    """One valid frame read from a segment: its byte range, seqs, append time and payload."""

    offset: int
    end: int
    seq: int
    """The seq of its (first) record."""
    timestamp_ms: int
    payload: bytes
    count: int = 1
    """Records in the frame (a group frame holds one or more)."""
    grouped: bool = False
    marks: bytes = b""
    """The frame's marks block (``edge.spool.marks``), empty when it has none (always copied)."""

    @property
    def last_seq(self) -> int:
        """The seq of the frame's last record."""
        return self.seq + self.count - 1

    def group(self) -> bytes:
        """The frame's records as a group (a single-record frame is wrapped in one)."""
        return self.payload if self.grouped else encode_group([self.payload])


@dataclass(frozen=True, slots=True)
class Damage:
    """Bytes ``[offset, end)`` hold no valid frame."""

    offset: int
    end: int
    reason: str


class _NeedMore:
    """The header is plausible but the frame runs past the bytes available."""

    __slots__ = ("end",)

    def __init__(self, end: int) -> None:
        self.end = end


def _header_problem(magic: int, flags: int, length: int, max_len: int) -> str | None:
    if magic != FRAME_MAGIC:
        return "bad frame magic"
    if flags & ~KNOWN_FLAGS or (flags & FLAG_MARKS and not flags & FLAG_GROUP):
        return f"unknown frame flags 0x{flags:04x}"
    if flags & FLAG_GROUP and length < GROUP_HEAD_SIZE:
        return f"group frame of {length} bytes is shorter than a group header"
    if length > max_len:
        return f"frame length {length} exceeds the {max_len}-byte limit"
    return None


def _contents(payload: memoryview, flags: int) -> tuple[memoryview, bytes, int] | str:
    """``(group or record payload, marks block, records)`` of a frame whose checksum holds,
    else why it is bad."""
    marks = b""
    if flags & FLAG_MARKS:
        try:
            size = marks_block_size(payload)
        except MarksError as exc:
            return str(exc)
        if len(payload) - size < GROUP_HEAD_SIZE:
            return "no record group before the marks block"
        payload, marks = payload[: len(payload) - size], bytes(payload[len(payload) - size :])
    count = group_count(payload) if flags & FLAG_GROUP else 1
    if count < 1:
        return "empty record group"
    return payload, marks, count


def frame_at(buf: bytes, off: int, end: int, max_len: int, *, copy: bool = True) -> Frame | _NeedMore | str:
    """The frame at ``off``; ``_NeedMore`` if it runs past ``end``; else the reason it is bad."""
    if end - off < HEADER_SIZE:
        return _NeedMore(off + HEADER_SIZE)
    magic, flags, length, seq, ts, crc = _FRAME.unpack_from(buf, off)
    problem = _header_problem(magic, flags, length, max_len)
    if problem is not None:
        return problem
    stop = off + HEADER_SIZE + length
    if stop > end:
        return _NeedMore(stop)
    view = memoryview(buf)
    payload = view[off + HEADER_SIZE : stop]
    if zlib.crc32(view[off : off + 24], zlib.crc32(payload)) != crc:
        return "checksum mismatch"
    contents = _contents(payload, flags)
    if isinstance(contents, str):
        return contents
    payload, marks, count = contents
    return Frame(
        offset=off,
        end=stop,
        seq=seq,
        timestamp_ms=ts,
        payload=bytes(payload) if copy else b"",
        count=count,
        grouped=bool(flags & FLAG_GROUP),
        marks=marks,
    )


def _resync(buf: bytes, start: int, end: int, max_len: int, after_seq: int) -> int:
    """Offset of the next valid frame after ``start`` (``end`` if none)."""
    pos = start
    while True:
        pos = buf.find(MAGIC_BYTES, pos + 1, end)
        if pos < 0:
            return end
        found = frame_at(buf, pos, end, max_len)
        if isinstance(found, Frame) and found.seq > after_seq:
            return pos


def scan(
    buf: bytes, start: int, end: int, *, max_len: int, final: bool, after_seq: int = -1, copy: bool = True
) -> Iterator[Frame | Damage]:
    """Frames and damaged ranges in ``buf[start:end]``, in order.

    ``final`` means ``end`` is the true end of the data: a frame running past it is a torn tail
    (damage). Otherwise scanning stops quietly before such a frame (read more and call again).
    Seqs must increase (beyond ``after_seq``); a valid frame that goes backwards is damage.
    ``copy=False`` leaves payloads empty (recovery only needs seqs and offsets).
    """
    off = start
    last_seq = after_seq
    while off < end:
        found = frame_at(buf, off, end, max_len, copy=copy)
        if isinstance(found, Frame) and found.seq <= last_seq:
            found = f"seq {found.seq} does not follow {last_seq}"
        if isinstance(found, Frame):
            yield found
            last_seq = found.last_seq
            off = found.end
            continue
        if isinstance(found, _NeedMore):
            if not final:
                return
            reason = f"truncated frame ({end - off} of {max(found.end - off, HEADER_SIZE)} bytes present)"
        else:
            reason = found
        resume = _resync(buf, off, end, max_len, last_seq)
        yield Damage(offset=off, end=resume, reason=reason)
        off = resume
