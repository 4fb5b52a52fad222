"""Per-publisher sequence tracking: gaps, duplicates and reordering from attachment sequence numbers.

Each rmw_zenoh publisher numbers its samples from 1 and its GID is unique per process run, so a
sequence that does not continue the last one from the same GID means samples were lost (gap) or
delivered twice / out of order.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass
from enum import Enum


class SeqStatus(Enum):
    """How a sequence number relates to the last one from the same publisher."""

    FIRST = "first"
    NEXT = "next"
    GAP = "gap"
    DUPLICATE = "duplicate"


@dataclass(frozen=True)
class SeqResult:
    """The status of one observed sequence number and, for a gap, how many were skipped."""

    status: SeqStatus
    missing: int = 0


_FIRST = SeqResult(SeqStatus.FIRST)
_NEXT = SeqResult(SeqStatus.NEXT)
_DUPLICATE = SeqResult(SeqStatus.DUPLICATE)


class SequenceTracker:
    """Remembers the last sequence number of up to ``max_sources`` publishers (least recent evicted)."""

    def __init__(self, max_sources: int = 4096) -> None:
        self.max_sources = max_sources
        self._last: OrderedDict[bytes, int] = OrderedDict()
        self.gaps = 0
        self.missing = 0
        self.duplicates = 0

    def observe(self, gid: bytes, seq: int) -> SeqResult:
        """Record ``seq`` from publisher ``gid``: its first, the next, after a gap, or a duplicate.

        A number at or below the last one counts as a duplicate and does not move the last one back.
        """
        last_seen = self._last
        last = last_seen.get(gid)
        if last is None:
            last_seen[gid] = seq  # a new key goes to the end: the most recent
            while len(last_seen) > self.max_sources:
                last_seen.popitem(last=False)
            return _FIRST
        if seq == last + 1:
            result = _NEXT
        elif seq > last + 1:
            result = SeqResult(SeqStatus.GAP, seq - last - 1)
            self.gaps += 1
            self.missing += result.missing
        else:
            self.duplicates += 1
            if len(last_seen) > 1:
                last_seen.move_to_end(gid)
            return _DUPLICATE
        last_seen[gid] = seq
        if len(last_seen) > 1:  # one publisher (the usual case): nothing to reorder
            last_seen.move_to_end(gid)
        return result

    def last(self, gid: bytes) -> int | None:
        """The last sequence number seen from ``gid`` (None when it is not tracked)."""
        return self._last.get(gid)

    @property
    def sources(self) -> int:
        """The number of publishers being tracked."""
        return len(self._last)
