"""The frames appended last, kept in memory for the sender (pure: no disk, no clock).

The sender reads records back moments after they were appended. Reading them from the segment
file means a ``pread`` of up to a batch, a CRC check and three objects per frame: measured, a
quarter of the edge's time per record at 30,000 records/s. ``RecentFrames`` keeps the chunks of
the last ``max_bytes`` appended, each with its segment and offset, so a read at the cursor is
answered from memory when the cursor is where the kept frames start; anything else (a sender
further behind, a reopened spool, a re-sent batch) reads the file as before. The frames kept are
the bytes that were written, so both ways give the same records.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence

from fleetlink.edge.spool.api import SpoolGroup
from fleetlink.edge.spool.frames import HEADER_SIZE, group_end
from fleetlink.edge.spool.segments import Segment

Item = tuple[int, int, int, bytes]
"""``(first seq, records, append time ms, group frame)``, as the spool writes them."""


class _Chunk:
    """Frames written by one write; ``index``/``offset``: the first one not yet read, and where."""

    __slots__ = ("index", "items", "nbytes", "offset", "segment")

    def __init__(self, segment: Segment, offset: int, items: Sequence[Item], nbytes: int) -> None:
        self.segment = segment
        self.offset = offset
        self.items = items
        self.index = 0
        self.nbytes = nbytes


class RecentFrames:
    """Chunks in append order, at most about ``max_bytes`` of frames (the oldest go first)."""

    def __init__(self, max_bytes: int = 32 << 20) -> None:
        self.max_bytes = max_bytes
        self._kept: deque[_Chunk] = deque()
        self._bytes = 0
        self.hits = 0
        """Reads answered from memory."""

    def add(self, segment: Segment, offset: int, items: Sequence[Item], nbytes: int) -> None:
        """``items`` (``nbytes`` of frames) were written to ``segment`` from ``offset`` on."""
        self._kept.append(_Chunk(segment, offset, items, nbytes))
        self._bytes += nbytes
        while self._bytes > self.max_bytes:
            self._bytes -= self._kept.popleft().nbytes

    def read(
        self, segment: Segment, offset: int, next_seq: int, *, max_records: int, max_bytes: int
    ) -> tuple[list[SpoolGroup], int] | None:
        """The groups at ``offset`` of ``segment`` on (at least one, at most ``max_records``
        records and, beyond the first, ``max_bytes`` of payload) and the offset after them;
        ``None`` if the frame there is not kept. Frames below ``next_seq`` (read already: seqs
        grow along the log) are forgotten."""
        kept = self._kept
        while kept:
            chunk = kept[0]
            items = chunk.items
            while chunk.index < len(items) and items[chunk.index][0] < next_seq:
                chunk.offset += len(items[chunk.index][3])
                chunk.index += 1
            if chunk.index < len(items):
                break
            self._bytes -= kept.popleft().nbytes
        if not kept or kept[0].segment is not segment or kept[0].offset != offset:
            return None
        groups: list[SpoolGroup] = []
        total = records = 0
        end = offset
        for chunk in kept:
            if chunk.segment is not segment or chunk.offset != end:  # chunks follow each other
                break
            items = chunk.items
            for i in range(chunk.index, len(items)):
                first, count, ts, frame = items[i]
                size = len(frame) - HEADER_SIZE
                if groups and (records + count > max_records or total + size > max_bytes):
                    self.hits += 1
                    return groups, end
                groups.append(SpoolGroup(first, count, ts, frame[HEADER_SIZE : group_end(frame)]))
                total += size
                records += count
                end += len(frame)
        self.hits += 1
        return groups, end

    def forget(self, segment: Segment) -> None:
        """``segment`` left the spool: drop its frames."""
        if any(chunk.segment is segment for chunk in self._kept):
            self._kept = deque(chunk for chunk in self._kept if chunk.segment is not segment)
            self._bytes = sum(chunk.nbytes for chunk in self._kept)

    def __len__(self) -> int:
        """Records kept and not yet read."""
        return sum(item[1] for chunk in self._kept for item in chunk.items[chunk.index :])
