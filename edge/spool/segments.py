"""Segment files: what the spool knows about each, and recovery of a directory at open.

``survey`` reads every segment once, checks every frame, compares each file with the ledger's
segment table (``edge.spool.ledger``) and reports, as ``edge.spool.damage.Finding``s with file,
byte range and seqs:
- damaged ranges (checksum, torn frame, bad header), counted as the records they lost: the seqs
  between the valid frames around them, or up to the last seq the ledger knew the file held;
- segments that hold fewer records than the ledger knew (cut short, zeroed) and segment files
  that are gone, counted from the ledger's table exactly;
- ledger files that are gone.
Seqs at or below the ack mark are in Kafka and never counted as lost. ``recover`` acts on the
survey: a torn tail of the newest segment is truncated away so appends continue on clean data;
segments wholly acknowledged, empty, holding nothing valid or deleted on purpose are deleted;
the sender resumes at the first record after the ack mark.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field, replace
from pathlib import Path

from fleetlink.edge.spool.damage import Finding, lost_range
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
from fleetlink.edge.spool.ledger import LEDGER_NAME, LedgerState

SEGMENT_NAME = re.compile(r"(\d{20})\.seg")


def segment_name(first_seq: int) -> str:
    """The file name of the segment whose first record has seq ``first_seq``."""
    return f"{first_seq:020d}.seg"


@dataclass(slots=True)
class Segment:
    """One segment file: its records' seqs and append time, its valid length and known damage."""

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
        """The known damaged range that starts at byte ``offset``; ``None`` when there is none."""
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
class SegmentScan:
    """One segment file as read at open: what it holds, what is damaged, what to cut off."""

    segment: Segment
    findings: list[Finding]
    truncate_at: int | None = None
    """A torn tail of the newest segment: the file is cut here so appends continue on clean data."""
    marks: list[bytes] = field(default_factory=list)
    """The marks blocks of its frames, in order."""


@dataclass(slots=True)
class Survey:
    """What a spool directory holds, read without changing anything (``survey``)."""

    scans: list[SegmentScan]
    findings: list[Finding]
    """Every finding, in seq order (ledger findings first)."""
    last_seq: int
    """The highest seq any segment holds or held (files and the ledger's table)."""
    gone: list[Path]
    """Segment files the ledger says were deleted on purpose (a crash came before the unlink)."""


@dataclass(slots=True)
class Recovery:
    """What ``recover`` left: the segments kept, where the sender resumes, the unacknowledged records they
    hold, the last seq, the damage found and the marks."""

    segments: list[Segment]
    cursor: Cursor
    depth: int
    last_seq: int
    findings: list[Finding]
    marks: list[bytes]
    """The marks blocks of every segment read (kept and spent), oldest first."""
    spent: list[Path]
    """Segments wholly acknowledged or empty: the spool deletes them once their marks are in the
    snapshot, so that a second crash cannot take the marks with them."""


def _lost(reason: str, path: Path, damage: Damage, seqs: tuple[int, int], ack_mark: int) -> Finding:
    first, last, records = lost_range(seqs[0], seqs[1], ack_mark)
    span = damage.end - damage.offset
    detail = f"{span} bytes: {damage.reason}" if span else damage.reason
    return Finding(reason, path.name, damage.offset, damage.end, first, last, records, detail)


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


def scan_segment(
    path: Path,
    data: bytes,
    first_seq: int,
    after_seq: int,
    max_len: int,
    *,
    newest: bool,
    extent: int | None,
    next_first: int | None,
    ack_mark: int,
) -> SegmentScan:
    """Read one segment file's bytes. ``extent`` is the last seq the ledger knew the segment
    held (``None``: not known). The records a damaged range lost are the seqs from the valid
    frame before it up to the next valid frame, else up to ``extent``; at the end of the newest
    segment beyond ``extent``, what is left of a torn frame's header (at least one); without a
    ledger table, up to ``next_first`` (the next segment's first seq). Seqs at or below
    ``ack_mark`` are in Kafka: never counted as lost."""
    segment = Segment(path=path, first_seq=first_seq, size=len(data))
    result = SegmentScan(segment, [])
    events: list[Frame | Damage] = []
    if decode_segment_header(data) is None:
        residue = len(data) < SEGMENT_HEADER_SIZE and (extent is None or extent < first_seq)
        if not residue:  # (a file cut before its header was written held nothing: a crash's trace)
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
    previous = max(after_seq, first_seq - 1)
    known_end = extent if extent is not None else -1
    for i, event in enumerate(events):
        if isinstance(event, Frame):
            segment.count += event.count
            segment.last_seq = previous = event.last_seq
            if segment.first_ts is None:
                segment.first_ts = event.timestamp_ms
            if event.marks:
                result.marks.append(event.marks)
            continue
        if event.offset == 0:  # a bad segment header loses no record
            result.findings.append(_lost("corrupt", path, event, (0, -1), ack_mark))
            segment.damage.append(event)
            continue
        after = next((e.seq for e in events[i + 1 :] if isinstance(e, Frame)), None)
        if after is not None:
            found = _lost("corrupt", path, event, (previous + 1, after - 1), ack_mark)
        else:
            found = _at_end(
                path,
                data,
                event,
                previous=previous,
                known_end=known_end,
                ack_mark=ack_mark,
                newest=newest,
                next_first=next_first,
            )
        result.findings.append(found)
        if newest and event.end == len(data):
            result.truncate_at = event.offset
            segment.size = event.offset
        else:
            segment.damage.append(event)
    ends_damaged = bool(result.findings) and result.findings[-1].end == len(data) and len(data) > 0
    if known_end > previous and not ends_damaged:
        why = f"the file ends after seq {previous}; the ledger knew seqs up to {known_end}"
        short = Damage(len(data), len(data), why)
        result.findings.append(_lost("truncated", path, short, (previous + 1, known_end), ack_mark))
    return result


def _at_end(
    path: Path,
    data: bytes,
    event: Damage,
    *,
    previous: int,
    known_end: int,
    ack_mark: int,
    newest: bool,
    next_first: int | None,
) -> Finding:
    """The finding for damage with no valid frame after it in its file."""
    if known_end > previous:  # damage within what the ledger knew the file held
        reason = "truncated" if event.reason.startswith("truncated frame") else "corrupt"
        return _lost(reason, path, event, (previous + 1, known_end), ack_mark)
    if newest:  # beyond the last fsync of the newest segment: a write a crash cut short
        records = _torn_records(data, event.offset, previous) or 1
        return _lost("torn_tail", path, event, (previous + 1, previous + records), -1)
    if known_end < 0 and next_first is not None:  # no ledger table: up to the next segment
        return _lost("corrupt", path, event, (previous + 1, next_first - 1), ack_mark)
    return _lost("corrupt", path, event, (previous + 1, previous + 1), ack_mark)


def survey(directory: Path, state: LedgerState, max_len: int) -> Survey:
    """Read every segment of ``directory`` (oldest first) against the ledger ``state``: what
    each holds and every damage: damaged ranges, segments shorter than the ledger knew, segment
    files gone, ledger files gone. Changes nothing (``recover`` acts on it)."""
    ack_mark = state.ack_mark
    findings: list[Finding] = []
    files = {
        int(p.name[:20]): p
        for p in (directory.iterdir() if directory.exists() else ())
        if SEGMENT_NAME.fullmatch(p.name)
    }
    table = state.segments if state.tracked else {}
    for name in state.missing:
        detail = "absent or empty; restored from the other copy"
        findings.append(Finding("ledger_missing", name, 0, 0, None, None, 0, detail))
    if state.fresh and files:
        detail = (
            "both ledger files are absent or empty beside segment files: what was acknowledged is not "
            "known, every record in the segments is sent again (duplicates)"
        )
        findings.append(Finding("ledger_missing", LEDGER_NAME, 0, 0, None, None, 0, detail))
    gone = [files.pop(first) for first in sorted(state.gone) if first in files and first not in table]
    firsts = sorted(set(files) | set(table))
    scans: list[SegmentScan] = []
    last_seq = -1
    unclean = state.clean_next_seq is None and not state.fresh
    for n, first in enumerate(firsts):
        newest = n == len(firsts) - 1
        extent = table.get(first)
        path = files.get(first)
        if path is None:
            path = directory / segment_name(first)
            hi = first - 1 if extent is None else extent
            last_seq = max(last_seq, hi)
            found = _lost(
                "segment_missing", path, Damage(0, 0, "the segment file is gone"), (first, hi), ack_mark
            )
            if newest and unclean:
                found = replace(
                    found,
                    detail=f"{found.detail}; records appended after seq {hi} in the last fsync interval "
                    f"before the unclean stop are not counted (seqs stay below {state.reserved})",
                )
            elif not found.records:
                continue  # acknowledged before it went
            findings.append(found)
            continue
        next_first = firsts[n + 1] if n + 1 < len(firsts) else None
        scanned = scan_segment(
            path,
            path.read_bytes(),
            first,
            last_seq,
            max_len,
            newest=newest,
            extent=extent,
            next_first=next_first,
            ack_mark=ack_mark,
        )
        findings.extend(scanned.findings)
        last_seq = max(last_seq, scanned.segment.last_seq, -1 if extent is None else extent)
        scans.append(scanned)
    return Survey(scans=scans, findings=findings, last_seq=last_seq, gone=gone)


def recover(directory: Path, state: LedgerState, max_len: int) -> Recovery:
    """Survey ``directory`` and act on it: cut torn tails, delete segments deleted on purpose, set
    apart those wholly acknowledged or empty (``Recovery.spent``); find where the sender resumes."""
    found = survey(directory, state, max_len)
    for path in found.gone:
        path.unlink()
    segments: list[Segment] = []
    marks: list[bytes] = []
    spent: list[Path] = []
    for scanned in found.scans:
        segment = scanned.segment
        if scanned.truncate_at is not None:
            with segment.path.open("r+b") as handle:
                handle.truncate(scanned.truncate_at)
        marks.extend(scanned.marks)
        if segment.count == 0 or segment.last_seq <= state.ack_mark:
            spent.append(segment.path)
            continue
        segments.append(segment)
    cursor, depth = _position(segments, state.ack_mark, max_len)
    return Recovery(
        segments=segments,
        cursor=cursor,
        depth=depth,
        last_seq=found.last_seq,
        findings=found.findings,
        marks=marks,
        spent=spent,
    )


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
