"""Publisher marks: written with the records they describe, restored at open, kept past the
segments that held them, never sent over the WAN."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from fleetlink.edge.spool import Spool, SpoolOptions
from fleetlink.edge.spool.frames import FLAG_MARKS, HEADER_SIZE, SEGMENT_HEADER_SIZE, Damage, Frame, scan
from fleetlink.edge.spool.marks import (
    MarkBook,
    MarksError,
    decode_marks,
    encode_marks,
    merge_marks,
    read_snapshot,
    write_snapshot,
)
from fleetlink.wire.groups import encode_group, group_payloads
from tests.unit.edge.spool.writes import count_writes

G1, G2, G3 = b"\x01" * 16, b"\x02" * 16, b"\x03" * 16
OPTIONS = SpoolOptions(segment_bytes=8192, max_bytes=1 << 20, group_records=10)
RECORD = b"r" * 100


def crash(spool: Spool) -> None:
    spool._stop.set()
    if spool._flusher is not None:
        spool._flusher.join()
    spool._ledger.close()
    os.close(spool._lock_fd)


def frames(directory: Path) -> list[Frame]:
    out: list[Frame] = []
    for path in sorted(directory.glob("*.seg")):
        data = path.read_bytes()
        out.extend(
            f
            for f in scan(data, SEGMENT_HEADER_SIZE, len(data), max_len=1 << 20, final=True)
            if not isinstance(f, Damage)
        )
    return out


def test_marks_blocks_and_snapshots_round_trip(tmp_path: Path) -> None:
    marks = [(G1, 5), (G2, -1), (G3, 1 << 40)]
    assert decode_marks(encode_marks(marks)) == marks
    assert decode_marks(encode_marks([])) == []
    assert encode_marks([(b"short", 3)]) == encode_marks([])  # not a GID: left out
    with pytest.raises(MarksError):
        decode_marks(encode_marks(marks)[1:])
    path = tmp_path / "marks"
    assert read_snapshot(path) == []
    write_snapshot(path, marks)
    assert read_snapshot(path) == marks
    data = bytearray(path.read_bytes())
    data[12] ^= 0x10
    path.write_bytes(bytes(data))
    assert read_snapshot(path) is None  # damaged: told apart from absent


def test_the_book_keeps_the_highest_seq_and_forgets_the_least_recent() -> None:
    book = MarkBook(limit=2)
    book.update([(G1, 5), (G2, 7)])
    book.update([(G1, 3)])  # older news never moves a mark back
    book.update([(G3, 1)])  # G2 is the least recently updated: forgotten
    assert dict(book.items()) == {G1: 5, G3: 1}


def test_a_block_replaces_the_marks_it_names_and_refreshes_them() -> None:
    book = MarkBook(limit=2)
    book.update([(G1, 5), (G2, 7)])
    book.add_block(encode_marks([(G1, 6)]))  # G1 updated last: G2 is the least recent now
    book.add_block(b"")  # no marks
    book.add_block(encode_marks([(G3, 1)]))
    assert book.items() == [(G1, 6), (G3, 1)]
    with pytest.raises(MarksError):
        book.add_block(encode_marks([(G1, 9)])[1:])


def test_merged_blocks_keep_the_highest_seq_of_each_publisher() -> None:
    merged = merge_marks(encode_marks([(G1, 5), (G2, 7)]), b"", encode_marks([(G1, 3), (G3, 1)]))
    assert sorted(decode_marks(merged)) == [(G1, 5), (G2, 7), (G3, 1)]
    assert merge_marks(b"", b"") == b""


def test_marks_go_with_the_last_group_of_the_next_append_and_come_back_at_open(tmp_path: Path) -> None:
    with Spool(tmp_path, OPTIONS) as spool:
        spool.note_marks(encode_marks([(G1, 10), (G2, 4)]))
        seqs = spool.append_many([RECORD] * 25)  # three groups: 10, 10, 5
        assert spool.marks() == [(G1, 10), (G2, 4)]
    marked = [f for f in frames(tmp_path) if f.marks]
    assert [(f.seq, f.count) for f in marked] == [(seqs[20], 5)]  # only the last group carries them
    with Spool(tmp_path, OPTIONS) as spool:
        assert sorted(spool.marks()) == [(G1, 10), (G2, 4)]


def test_sent_groups_never_carry_the_marks(tmp_path: Path) -> None:
    group = encode_group([RECORD] * 3)
    with Spool(tmp_path, OPTIONS) as spool:
        spool.note_marks(encode_marks([(G1, 10)]))
        spool.append_group(group)
        batch = spool.read_unacked(100, 1 << 20)  # from memory, as written
        assert batch is not None
        assert [g.group for g in batch.groups] == [group]
        spool.release(batch.first_seq)
        again = spool.read_unacked(100, 1 << 20)  # re-read from the file
        assert again is not None
        assert [g.group for g in again.groups] == [group]
        assert [r.payload for r in again.records] == group_payloads(group)
    (frame,) = frames(tmp_path)
    raw = next(tmp_path.glob("*.seg")).read_bytes()[SEGMENT_HEADER_SIZE:]
    assert int.from_bytes(raw[2:4], "little") & FLAG_MARKS
    assert frame.payload == group
    assert len(raw) == HEADER_SIZE + len(group) + len(encode_marks([(G1, 10)]))


def test_marks_outlive_the_segments_that_held_them(tmp_path: Path) -> None:
    with Spool(tmp_path, OPTIONS) as spool:
        for n in range(1, 6):
            spool.note_marks(encode_marks([(G1, n * 100), (bytes([n + 10]) * 16, n)]))
            spool.append_many([RECORD] * 30)
        while (batch := spool.read_unacked(1000, 1 << 20)) is not None:
            spool.ack(batch.first_seq)
        assert len(list(tmp_path.glob("*.seg"))) <= 1  # acked segments are gone with their frames
    with Spool(tmp_path, OPTIONS) as spool:
        marks = dict(spool.marks())
    assert marks[G1] == 500
    assert {marks[bytes([n + 10]) * 16] for n in range(1, 6)} == {1, 2, 3, 4, 5}


def test_after_a_crash_the_marks_say_exactly_what_reached_the_spool(tmp_path: Path) -> None:
    spool = Spool(tmp_path, OPTIONS).open()
    spool.note_marks(encode_marks([(G1, 10)]))
    spool.append_many([RECORD] * 3)
    spool.note_marks(encode_marks([(G1, 20), (G2, 7)]))
    spool.append_many([RECORD] * 3)
    spool.note_marks(encode_marks([(G1, 30)]))  # a chunk that made no record for the spool: not written yet
    crash(spool)
    segment = next(tmp_path.glob("*.seg"))
    with segment.open("r+b") as handle:  # the second write was cut short by the crash
        handle.truncate(segment.stat().st_size - 20)
    with Spool(tmp_path, OPTIONS) as spool:
        assert spool.marks() == [(G1, 10)]
        assert spool.stats().corrupt_skipped == 3  # the torn group's records, never taken


def test_an_append_that_would_cross_a_segment_boundary_is_one_write_in_a_new_segment(
    tmp_path: Path,
) -> None:
    # split over two writes (the groups that fit to the old segment, the rest with the marks to
    # a new one), a crash between them would leave records spooled that no mark covers: the
    # restart would count them lost although they reach Kafka
    with Spool(tmp_path, OPTIONS) as spool:
        spool.note_marks(encode_marks([(G1, 40)]))
        spool.append_many([RECORD] * 40)  # about 4.4 KB of the 8 KiB segment
        before = {p.name: p.stat().st_size for p in tmp_path.glob("*.seg")}
        spool.note_marks(encode_marks([(G1, 80)]))
        seqs = spool.append_many([RECORD] * 40)  # four groups: they do not all fit what is left
        assert spool.marks() == [(G1, 80)]
    (old,) = before
    assert (tmp_path / old).stat().st_size == before[old]  # nothing of the second append in it
    first = seqs[0]
    assert first is not None
    second = [f for f in frames(tmp_path) if f.seq >= first]
    assert [(f.seq, f.count) for f in second] == [(seqs[n], 10) for n in range(0, 40, 10)]
    assert [bool(f.marks) for f in second] == [False, False, False, True]
    assert len(list(tmp_path.glob("*.seg"))) == 2


def test_an_append_larger_than_a_segment_is_one_write_in_a_segment_of_its_own(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    writes = count_writes(monkeypatch)
    with Spool(tmp_path, OPTIONS) as spool:
        spool.append_many([RECORD] * 5)
        spool.note_marks(encode_marks([(G1, 100)]))
        seqs = spool.append_many([RECORD] * 100)  # about 11 KB: more than one 8 KiB segment
        spool.append_many([RECORD] * 5)
        assert writes == [1, 10, 1]
    assert len(list(tmp_path.glob("*.seg"))) == 3
    with Spool(tmp_path, OPTIONS) as spool:
        assert spool.marks() == [(G1, 100)]
        got: list[int] = []
        while (batch := spool.read_unacked(1000, 1 << 20)) is not None:
            got.extend(r.seq for r in batch.records)
            spool.ack(batch.first_seq)
    assert got[5:105] == seqs
    assert len(got) == 110


def test_marks_wait_for_a_write_that_takes_their_group(tmp_path: Path) -> None:
    options = SpoolOptions(segment_bytes=4096, max_bytes=8192, policy="drop_newest", group_records=10)
    with Spool(tmp_path, options) as spool:
        while spool.append(RECORD * 10) is not None:
            pass  # full
        spool.note_marks(encode_marks([(G1, 99)]))
        assert spool.append_many([RECORD * 10]) == [None]  # refused: the marks stay pending
        assert spool.marks() == []
        while (batch := spool.read_unacked(100, 1 << 20)) is not None:
            spool.ack(batch.first_seq)
        assert spool.append(RECORD) is not None
        assert spool.marks() == [(G1, 99)]


def test_pending_marks_are_kept_by_a_clean_close(tmp_path: Path) -> None:
    with Spool(tmp_path, OPTIONS) as spool:
        spool.note_marks(encode_marks([(G3, 42)]))  # samples that made no durable record, then a clean stop
    with Spool(tmp_path, OPTIONS) as spool:
        assert spool.marks() == [(G3, 42)]


def test_marks_of_segments_deleted_at_open_survive_a_second_crash(tmp_path: Path) -> None:
    # a crash after the ack but before the acked segment went: the next open deletes the segment;
    # if its marks were then only in memory, a second crash would seed the older snapshot and
    # count the robots' samples since then as lost at restart
    spool = Spool(tmp_path, OPTIONS).open()
    spool.note_marks(encode_marks([(G1, 10)]))
    spool.append_many([RECORD] * 3)
    spool.note_marks(encode_marks([(G1, 20), (G2, 7)]))
    spool.append_many([RECORD] * 3)
    while (batch := spool.read_unacked(100, 1 << 20)) is not None:
        spool.ack(batch.first_seq)
    crash(spool)
    assert list(tmp_path.glob("*.seg"))  # acknowledged, still on disk
    spool = Spool(tmp_path, OPTIONS).open()
    assert not list(tmp_path.glob("*.seg"))  # spent: deleted at open
    assert sorted(spool.marks()) == [(G1, 20), (G2, 7)]
    crash(spool)  # before anything else was appended or snapshotted
    with Spool(tmp_path, OPTIONS) as spool:
        assert sorted(spool.marks()) == [(G1, 20), (G2, 7)]


def test_a_spent_segment_stays_while_the_snapshot_cannot_be_written(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    spool = Spool(tmp_path, OPTIONS).open()
    spool.note_marks(encode_marks([(G1, 10)]))
    spool.append_many([RECORD] * 3)
    while (batch := spool.read_unacked(100, 1 << 20)) is not None:
        spool.ack(batch.first_seq)
    crash(spool)

    def refuse(path: Path, marks: object) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr("fleetlink.edge.spool.spool.write_snapshot", refuse)
    spool = Spool(tmp_path, OPTIONS).open()
    assert list(tmp_path.glob("*.seg"))  # kept: its marks are nowhere else on disk
    assert spool.marks() == [(G1, 10)]
    crash(spool)
    monkeypatch.undo()
    with Spool(tmp_path, OPTIONS) as spool:
        assert spool.marks() == [(G1, 10)]
        assert spool.stats().depth == 0
    assert not list(tmp_path.glob("*.seg"))
