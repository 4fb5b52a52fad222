"""Frames appended lately, read from memory: the same groups as from the file, or none."""

from __future__ import annotations

from pathlib import Path

import pytest

from fleetlink.edge.spool import Spool, SpoolGroup, SpoolOptions
from fleetlink.edge.spool.frames import HEADER_SIZE, SEGMENT_HEADER_SIZE, encode_group_frame
from fleetlink.edge.spool.recent import Item, RecentFrames
from fleetlink.edge.spool.segments import Segment
from fleetlink.wire.groups import encode_group


def group(seq: int, size: int = 10) -> bytes:
    return encode_group([bytes([seq % 256]) * size])


def items(first_seq: int, n: int) -> list[Item]:
    """Frames of one record each."""
    return [
        (seq, 1, 1000 + seq, encode_group_frame(seq, 1000 + seq, group(seq)))
        for seq in range(first_seq, first_seq + n)
    ]


def nbytes(chunk: list[Item]) -> int:
    return sum(len(item[3]) for item in chunk)


SEG_A = Segment(path=Path("a.seg"), first_seq=1, size=SEGMENT_HEADER_SIZE)
SEG_B = Segment(path=Path("b.seg"), first_seq=100, size=SEGMENT_HEADER_SIZE)
GROUP = len(group(1))
FRAME = HEADER_SIZE + GROUP


def filled(max_bytes: int = 1 << 20) -> RecentFrames:
    """Seqs 1..5 then 6..8 in segment A (two writes), 100..101 in segment B."""
    recent = RecentFrames(max_bytes)
    for segment, offset, chunk in (
        (SEG_A, 16, items(1, 5)),
        (SEG_A, 16 + 5 * FRAME, items(6, 3)),
        (SEG_B, 16, items(100, 2)),
    ):
        recent.add(segment, offset, chunk, nbytes(chunk))
    return recent


@pytest.mark.parametrize(
    ("segment", "offset", "next_seq", "max_records", "max_bytes", "seqs", "end"),
    [
        (SEG_A, 16, 1, 100, 1 << 20, [1, 2, 3, 4, 5, 6, 7, 8], 16 + 8 * FRAME),  # across writes, not segments
        (SEG_A, 16, 1, 3, 1 << 20, [1, 2, 3], 16 + 3 * FRAME),
        (SEG_A, 16, 1, 100, 2 * GROUP + 5, [1, 2], 16 + 2 * FRAME),
        (SEG_A, 16, 1, 100, 1, [1], 16 + FRAME),  # at least one
        (SEG_A, 16 + 3 * FRAME, 4, 100, 1 << 20, [4, 5, 6, 7, 8], 16 + 8 * FRAME),
        (SEG_A, 16 + 6 * FRAME, 7, 1, 1 << 20, [7], 16 + 7 * FRAME),
        (SEG_B, 16, 100, 100, 1 << 20, [100, 101], 16 + 2 * FRAME),
    ],
)
def test_reads_at_the_cursor(
    segment: Segment, offset: int, next_seq: int, max_records: int, max_bytes: int, seqs: list[int], end: int
) -> None:
    found = filled().read(segment, offset, next_seq, max_records=max_records, max_bytes=max_bytes)
    assert found is not None
    groups, got_end = found
    assert [g.first_seq for g in groups] == seqs
    assert groups[0] == SpoolGroup(seqs[0], 1, 1000 + seqs[0], group(seqs[0]))
    assert got_end == end


@pytest.mark.parametrize(
    ("segment", "offset", "next_seq"),
    [
        (SEG_A, 16 + FRAME, 1),  # not where the kept frames start
        (SEG_B, 16, 1),  # segment A's frames come first
        (SEG_A, 16, 9),  # everything of A was read: nothing there any more
    ],
)
def test_misses_when_the_frame_there_is_not_the_next_kept(
    segment: Segment, offset: int, next_seq: int
) -> None:
    assert filled().read(segment, offset, next_seq, max_records=10, max_bytes=1 << 20) is None


def test_read_frames_are_forgotten_and_segment_b_follows() -> None:
    recent = filled()
    assert len(recent) == 10
    first = recent.read(SEG_A, 16, 1, max_records=8, max_bytes=1 << 20)
    assert first is not None
    assert recent.read(SEG_B, 16, 9, max_records=8, max_bytes=1 << 20) is not None
    assert len(recent) == 2
    assert recent.hits == 2


def test_oldest_writes_go_beyond_max_bytes_and_forget_drops_a_segment() -> None:
    recent = filled(max_bytes=3 * FRAME + 2 * FRAME)  # room for the last two writes only
    assert recent.read(SEG_A, 16, 1, max_records=10, max_bytes=1 << 20) is None
    kept = recent.read(SEG_A, 16 + 5 * FRAME, 6, max_records=10, max_bytes=1 << 20)
    assert kept is not None
    assert [g.first_seq for g in kept[0]] == [6, 7, 8]
    recent.forget(SEG_B)
    assert recent.read(SEG_B, 16, 9, max_records=10, max_bytes=1 << 20) is None
    assert len(recent) == 0


def test_spool_reads_lately_appended_records_from_memory_and_the_same_from_disk(tmp_path: Path) -> None:
    payloads = [f"record-{i}".encode() * 5 for i in range(50)]
    with Spool(tmp_path, SpoolOptions(segment_bytes=4096, max_bytes=1 << 20, group_records=7)) as spool:
        spool.append_many(payloads)
        memory = []
        while (batch := spool.read_unacked(7, 1 << 20)) is not None:
            memory.append(batch)
        assert spool._recent.hits >= 1
        spool.release_all()
        disk = []
        while (batch := spool.read_unacked(7, 1 << 20)) is not None:
            disk.append(batch)
    assert [r for b in memory for r in b.records] == [r for b in disk for r in b.records]
    assert [r.payload for b in memory for r in b.records] == payloads
    assert [(b.first_seq, b.last_seq) for b in memory] == [(b.first_seq, b.last_seq) for b in disk]
