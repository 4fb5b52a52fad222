"""A spool with one 100-byte record per frame, for tests that damage its files on purpose."""

from __future__ import annotations

from pathlib import Path

from fleetlink.edge.spool import Spool, SpoolOptions
from fleetlink.edge.spool.frames import HEADER_SIZE
from fleetlink.wire.groups import HEAD_SIZE

GROUP_OVERHEAD = HEAD_SIZE + 4  # the group header and the record's length

OPTIONS = SpoolOptions(segment_bytes=8192, max_bytes=1 << 20, group_records=1)  # a frame per record
RECORD = b"p" * 100
FRAME = HEADER_SIZE + GROUP_OVERHEAD + len(RECORD)  # a group of one record per frame


def fill(directory: Path, count: int, *, ack_first: int = 0) -> list[Path]:
    """Append ``count`` records one at a time (acknowledging the first ``ack_first``); the
    segment files. (An append is one write in one segment: one at a time, they fill segments.)"""
    with Spool(directory, OPTIONS) as spool:
        for _ in range(count):
            spool.append(RECORD)
        if ack_first:
            batch = spool.read_unacked(ack_first, 1 << 20)
            assert batch is not None
            assert batch.count == ack_first
            spool.ack(batch.first_seq)
    return sorted(directory.glob("*.seg"))


def reopen_and_read(directory: Path) -> tuple[list[int], Spool]:
    """Open the spool again and read (and acknowledge) every record: their seqs, and the spool."""
    spool = Spool(directory, OPTIONS).open()
    seqs: list[int] = []
    while (batch := spool.read_unacked(1000, 1 << 20)) is not None:
        seqs.extend(r.seq for r in batch.records)
        spool.ack(batch.first_seq)
    return seqs, spool
