"""Counting the spool's writes: how many frames each ``SegmentWriter.write`` call carried."""

from __future__ import annotations

import pytest

from fleetlink.edge.spool.writer import SegmentWriter


def count_writes(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """From now on, the number of frames of each write, in order (the list fills as they happen)."""
    writes: list[int] = []
    real = SegmentWriter.write

    def counting(self: SegmentWriter, data: bytes, items: list[tuple[int, int, int, int]]) -> None:
        writes.append(len(items))
        real(self, data, items)

    monkeypatch.setattr(SegmentWriter, "write", counting)
    return writes
