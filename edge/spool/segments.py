"""Segment files: what the spool knows about each, and recovery of a directory at open.

Recovery reads every segment once, checks every frame, and reports:
- damaged ranges (checksum, torn frame, bad header), each logged once with file and offset and
  counted as the records it lost (the seq gap around it, at least 1);
- a torn tail of the newest segment is truncated away so appends continue on clean data;
- segments wholly acknowledged, empty, or holding nothing valid are deleted;
- where the sender resumes: the first record after the ack mark.
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass, field
from pathlib import Path

from fleetlink.edge.spool.frames import (
    FLAG_GROUP,
    FRAME_HEADER,
    FRAME_MAGIC,
    HEADER_SIZE,
    SEGMENT_HEADER_SIZE,
    Damage,
    Frame,
    decode_segment_header,
    scan,
)

log = logging.getLogger(__name__)

SEGMENT_NAME = re.compile(r"(\d{20})\.seg")
MAX_DAMAGE_LOGS_PER_FILE = 10


def segment_name(first_seq: int) -> str:
    return f"{first_seq:020d}.seg"


@dataclass(slots=True)
class Segment:
    path: Path
    first_seq: int
    size: int
    """End of the valid data: the file's length."""
    count: int = 0
    """Valid records in the file."""
    last_seq: int = -1
    first_ts: int | None = None
    damage: list[Damage] = field(default_factory=list)
    """Known damaged ranges, skipped when reading."""
    sealed: bool = True

    def __post_init__(self) -> None:
        if self.last_seq < 0:
            self.last_seq = self.first_seq - 1

    def damage_at(self, offset: int) -> Damage | None:
        for damage in self.damage:
            if damage.offset == offset:
                return damage
        return None


@dataclass(slots=True)
class Cursor:
    """Where the sender reads next: ``index`` into the segment list, byte ``offset``, records of
    that segment already behind it (``consumed``) and the seq every unread record exceeds."""

    index: int = 0
    offset: int = SEGMENT_HEADER_SIZE
    consumed: int = 0
    next_seq: int = 1


@dataclass(slots=True)
class Recovery:
    segments: list[Segment]
    cursor: Cursor
    depth: int
    last_seq: int
    corrupt_records: int


def _lost_between(before: int, after: int | None) -> int:
    if after is None or before < 0:
        return 1
    return max(1, after - before - 1)


def _torn_records(data: bytes, offset: int, before: int) -> int | None:
    """The records of a frame torn at the end of the data, read from what is left of its header
    (a seq that follows ``before``, a group's count): ``None`` when that is not readable."""
    if len(data) - offset < HEADER_SIZE:
        return None
    magic, flags, _length, seq, _ts, _crc = FRAME_HEADER.unpack_from(data, offset)
    if magic != FRAME_MAGIC or seq <= before or before < 0:
        return None
    if not flags & FLAG_GROUP:
        return int(seq - before)
    if len(data) - offset < HEADER_SIZE + 4:
        return None
    count = int.from_bytes(data[offset + HEADER_SIZE : offset + HEADER_SIZE + 4], "little")
    return seq - before - 1 + count if count > 0 else None


def _scan_file(
    path: Path, first_seq: int, after_seq: int, max_len: int, *, newest: bool, next_first: int | None = None
) -> tuple[Segment, int]:
    """Scan one file; returns its segment and the records lost to damage in it. Losses come from
    the seqs around the damage (the next frame's, else ``next_first``: the next segment's first
    seq, else what is left of a torn frame's header)."""
    data = path.read_bytes()
    segment = Segment(path=path, first_seq=first_seq, size=len(data))
    events: list[Frame | Damage] = []
    if decode_segment_header(data) is None:
        events.append(Damage(0, min(len(data), SEGMENT_HEADER_SIZE), "not a spool segment header"))
    events.extend(
        scan(
            data,
            SEGMENT_HEADER_SIZE,
            len(data),
            max_len=max_len,
            final=True,
            after_seq=max(after_seq, first_seq - 1),
            copy=False,
        )
    )
    lost = 0
    logged = 0
    previous = max(after_seq, first_seq - 1)
    for i, event in enumerate(events):
        if isinstance(event, Frame):
            segment.count += event.count
            segment.last_seq = previous = event.last_seq
            if segment.first_ts is None:
                segment.first_ts = event.timestamp_ms
            continue
        after = next((e.seq for e in events[i + 1 :] if isinstance(e, Frame)), next_first)
        if event.offset == 0:
            records = 0  # a bad segment header loses no record
        elif after is None:
            records = _torn_records(data, event.offset, previous) or 1
        else:
            records = _lost_between(previous, after)
        lost += records
        at_end = event.end == len(data) and after is None
        torn_tail = newest and at_end and event.offset >= SEGMENT_HEADER_SIZE
        if logged < MAX_DAMAGE_LOGS_PER_FILE:
            what = "torn tail" if torn_tail else "corrupt data"
            log.error(
                "spool: %s in %s at offset %d (%d bytes: %s); %d record(s) skipped",
                what,
                path,
                event.offset,
                event.end - event.offset,
                event.reason,
                records,
            )
            logged += 1
        if torn_tail:
            with path.open("r+b") as handle:
                handle.truncate(event.offset)
            segment.size = event.offset
        else:
            segment.damage.append(event)
    if logged < len(segment.damage):
        log.error("spool: %s has %d damaged ranges in all", path, len(segment.damage))
    return segment, lost


def recover(directory: Path, ack_mark: int, max_len: int) -> Recovery:
    """Scan ``directory``'s segments (oldest first) and decide what stays."""
    names = sorted(p for p in directory.iterdir() if SEGMENT_NAME.fullmatch(p.name))
    segments: list[Segment] = []
    corrupt = 0
    last_seq = -1
    for n, path in enumerate(names):
        first_seq = int(path.name[:20])
        next_first = int(names[n + 1].name[:20]) if n + 1 < len(names) else None
        segment, lost = _scan_file(
            path, first_seq, last_seq, max_len, newest=n == len(names) - 1, next_first=next_first
        )
        corrupt += lost
        last_seq = max(last_seq, segment.last_seq)
        if segment.count == 0 or segment.last_seq <= ack_mark:
            path.unlink()
            continue
        segments.append(segment)
    cursor, depth = _position(segments, ack_mark, max_len)
    return Recovery(segments=segments, cursor=cursor, depth=depth, last_seq=last_seq, corrupt_records=corrupt)


def _position(segments: list[Segment], ack_mark: int, max_len: int) -> tuple[Cursor, int]:
    """The cursor at the first record after ``ack_mark``, and how many records follow it."""
    depth = sum(s.count for s in segments)
    if not segments:
        return Cursor(next_seq=ack_mark + 1), 0
    first = segments[0]
    if first.first_seq > ack_mark:
        return Cursor(next_seq=ack_mark + 1), depth
    data = first.path.read_bytes()
    consumed = 0
    for event in scan(data, SEGMENT_HEADER_SIZE, first.size, max_len=max_len, final=True, copy=False):
        if isinstance(event, Frame):
            if event.last_seq > ack_mark:  # (a group the mark falls inside is sent again whole)
                return Cursor(0, event.offset, consumed, event.seq), depth - consumed
            consumed += event.count
    return Cursor(0, first.size, consumed, ack_mark + 1), depth - consumed  # pragma: no cover
