"""Send-side bookkeeping (pure): what is unread, in flight, to be re-sent; the ack mark.

Invariant: every record with a seq below ``cursor.next_seq`` that is in no in-flight or retry
slice has been acknowledged (or dropped). Hence the ack mark, the highest seq below which
everything is done, is ``min(cursor.next_seq, in-flight and retry first seqs) - 1`` and never
needs a per-record set. Acks may arrive in any order; the mark advances when the oldest does.
"""

from __future__ import annotations

from dataclasses import dataclass

from fleetlink.edge.spool.frames import SEGMENT_HEADER_SIZE
from fleetlink.edge.spool.segments import Cursor, Segment


@dataclass(slots=True)
class Slice:
    """A batch handed to the sender: seqs ``first..last`` at ``[offset, end)`` of ``segment``."""

    first_seq: int
    last_seq: int
    count: int
    segment: Segment
    offset: int
    end: int
    first_ts: int
    orphan: bool = False
    """Its segment was evicted (``drop_oldest``) while it was in flight."""


class SendTracker:
    """Tracks what the sender has read, has in flight and must re-send, and from that the ack mark."""

    def __init__(self, cursor: Cursor) -> None:
        self.cursor = cursor
        self.in_flight: dict[int, Slice] = {}
        self.retry: dict[int, Slice] = {}

    def mark(self) -> int:
        """The ack mark: every seq up to it is acknowledged (or dropped)."""
        return min((self.cursor.next_seq, *self.in_flight, *self.retry)) - 1

    def take_retry(self) -> Slice | None:
        """The oldest released slice, now in flight again."""
        if not self.retry:
            return None
        found = self.retry.pop(min(self.retry))
        self.in_flight[found.first_seq] = found
        return found

    def start(self, found: Slice, consumed: int) -> None:
        """A fresh slice was read at the cursor (``consumed`` records, damage skipped)."""
        self.in_flight[found.first_seq] = found
        self.cursor.offset = found.end
        self.cursor.consumed += consumed
        self.cursor.next_seq = max(self.cursor.next_seq, found.last_seq + 1)

    def resume(self, found: Slice) -> None:
        """What is left of a released slice read again (damaged since), in flight again."""
        self.in_flight[found.first_seq] = found

    def finish(self, first_seq: int) -> Slice | None:
        """The slice starting at ``first_seq`` is acknowledged (also accepted while released)."""
        found = self.in_flight.pop(first_seq, None)
        if found is None:
            found = self.retry.pop(first_seq, None)
        return found

    def release(self, first_seq: int) -> Slice | None:
        """Back to the retry queue; an orphan is returned and forgotten (its records are gone)."""
        found = self.in_flight.pop(first_seq, None)
        if found is not None and not found.orphan:
            self.retry[first_seq] = found
        return found

    def segment_removed(self, segment: Segment) -> tuple[int, int]:
        """``segment`` (the oldest) leaves the spool. Returns ``(dropped, orphaned)`` record
        counts: unread or queued for re-sending (lost now), and in flight (lost unless acked)."""
        dropped = 0
        if self.cursor.index == 0:
            dropped += max(0, segment.count - self.cursor.consumed)
            self.cursor.offset = SEGMENT_HEADER_SIZE
            self.cursor.consumed = 0
            self.cursor.next_seq = max(self.cursor.next_seq, segment.last_seq + 1)
        else:
            self.cursor.index -= 1
        for first, queued in list(self.retry.items()):
            if queued.segment is segment:
                dropped += queued.count
                del self.retry[first]
        orphaned = 0
        for flying in self.in_flight.values():
            if flying.segment is segment and not flying.orphan:
                flying.orphan = True
                orphaned += flying.count
        return dropped, orphaned

    def in_flight_records(self) -> int:
        """Records in flight, without those of evicted segments."""
        return sum(s.count for s in self.in_flight.values() if not s.orphan)

    def oldest_ts(self) -> int | None:
        """The append time (ms) of the oldest in-flight or released batch; ``None`` when there is none."""
        stamps = [s.first_ts for s in (*self.in_flight.values(), *self.retry.values()) if not s.orphan]
        return min(stamps, default=None)
