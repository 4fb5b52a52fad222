"""Reading frames back from a segment file for the sender (bounded by records and bytes)."""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass, field

from fleetlink.edge.spool.frames import HEADER_SIZE, Damage, Frame, scan
from fleetlink.edge.spool.segments import Segment

log = logging.getLogger(__name__)

READ_SLACK = 64 * 1024


@dataclass(slots=True)
class ReadResult:
    """What one read of a segment brought: valid frames, where it stopped, and damage met."""

    frames: list[Frame]
    end: int
    """Absolute offset just after what was consumed (frames and damage)."""
    lost: int = 0
    """Records lost to damage not seen before (now recorded in ``segment.damage``)."""
    damaged: list[tuple[Damage, int, int]] = field(default_factory=list)
    """That damage: ``(range, first seq lost, last seq lost)`` (the seqs up to the next frame
    read; one record when no frame follows it in what was read)."""


def _pread(path: os.PathLike[str] | str, size: int, offset: int) -> bytes:
    fd = os.open(path, os.O_RDONLY)
    try:
        return os.pread(fd, size, offset)
    finally:
        os.close(fd)


def read_frames(
    segment: Segment,
    start: int,
    limit: int,
    *,
    after_seq: int,
    max_records: int,
    max_bytes: int,
    max_len: int,
) -> ReadResult:
    """Frames from ``start`` up to ``limit`` (the segment's valid end), at least one if any, at
    most ``max_records`` records and, beyond the first frame, ``max_bytes`` of payload. Known
    damage is skipped silently; new damage is logged, recorded on the segment and counted in
    ``lost``."""
    size = min(limit - start, max_bytes + max_records * HEADER_SIZE + READ_SLACK)
    while True:
        data = _pread(segment.path, size, start)
        # a short read: the file ends here (cut short under the spool), nothing more will come
        final = start + len(data) >= limit or len(data) < size
        result = ReadResult(frames=[], end=start)
        total = 0
        records = 0
        pending: Damage | None = None
        for event in scan(data, 0, len(data), max_len=max_len, final=final, after_seq=after_seq):
            if isinstance(event, Damage):
                if not final and event.end == len(data):
                    break  # the damage may run past this chunk: re-read to the segment's end
                pending = _note_damage(segment, start, event, result, pending, after_seq=after_seq)
                result.end = start + event.end
                continue
            full = records + event.count > max_records or total + len(event.payload) > max_bytes
            if result.frames and full:
                break
            if pending is not None:
                result.lost += max(1, event.seq - after_seq - 1) - 1  # refine the gap estimate
                damage, lo, _hi = result.damaged[-1]
                result.damaged[-1] = (damage, lo, max(lo, event.seq - 1))
                pending = None
            result.frames.append(
                Frame(
                    start + event.offset,
                    start + event.end,
                    event.seq,
                    event.timestamp_ms,
                    event.payload,
                    event.count,
                    event.grouped,
                )
            )
            total += len(event.payload)
            records += event.count
            after_seq = event.last_seq
            result.end = start + event.end
        if result.frames or result.end > start or final:
            return result
        size = limit - start  # nothing complete in the chunk: read everything that is left


def _note_damage(
    segment: Segment, start: int, event: Damage, result: ReadResult, pending: Damage | None, *, after_seq: int
) -> Damage | None:
    absolute = Damage(start + event.offset, start + event.end, event.reason)
    if segment.damage_at(absolute.offset) is not None:
        return pending
    segment.damage.append(absolute)
    result.lost += 1
    result.damaged.append((absolute, after_seq + 1, after_seq + 1))
    log.error(
        "spool: corrupt data in %s at offset %d (%d bytes: %s); skipped",
        segment.path,
        absolute.offset,
        absolute.end - absolute.offset,
        absolute.reason,
    )
    return absolute
