"""Spool damage that used to go uncounted: segments deleted, zeroed or cut short, all segments
gone with the ledger kept, a crashed run's newest segment gone. Each is counted exactly from the
ledger's segment table, logged with file and seq range, reported until acknowledged, and never
counted twice."""

from __future__ import annotations

import logging
import os
from pathlib import Path

import pytest

from fleetlink.edge.spool import Spool, SpoolOptions
from fleetlink.edge.spool.frames import HEADER_SIZE, SEGMENT_HEADER_SIZE
from tests.unit.edge.spool.one_record_frames import FRAME, OPTIONS, RECORD, fill, reopen_and_read

PER_SEGMENT = (OPTIONS.segment_bytes - SEGMENT_HEADER_SIZE) // FRAME


def crash(spool: Spool) -> None:
    """What kill -9 leaves: the files as written, no clean close, the lock released."""
    spool._stop.set()
    if spool._flusher is not None:
        spool._flusher.join()
    spool._ledger.close()
    os.close(spool._lock_fd)


def seqs_of(path: Path, following: Path | None, last: int) -> range:
    """The seqs a segment file held (files are named by their first seq)."""
    first = int(path.name[:20])
    return range(first, int(following.name[:20]) if following is not None else last + 1)


def test_a_deleted_middle_segment_is_counted_exactly_once_and_reported_until_acknowledged(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    segments = fill(tmp_path, 200)
    gone = seqs_of(segments[1], segments[2], 200)
    segments[1].unlink()
    caplog.set_level(logging.ERROR)
    seqs, spool = reopen_and_read(tmp_path)
    assert seqs == [s for s in range(1, 201) if s not in gone]
    stats = spool.stats()
    assert stats.lost_missing == len(gone) == PER_SEGMENT
    assert stats.corrupt_skipped == 0
    assert stats.damage_unacknowledged == 1
    assert f"segment {segments[1]} is missing" in caplog.text
    assert f"{len(gone)} record(s) lost (seqs {gone[0]}..{gone[-1]})" in caplog.text
    spool.close()

    caplog.clear()
    _seqs, spool = reopen_and_read(tmp_path)  # reopened: the same damage is not counted again ...
    assert spool.stats().lost_missing == 0
    assert "is missing" not in caplog.text
    assert spool.stats().damage_unacknowledged == 1  # ... but still awaits an operator
    (finding,) = spool.acknowledge_damage()
    assert (finding.reason, finding.file, finding.first_seq, finding.last_seq, finding.records) == (
        "segment_missing",
        segments[1].name,
        gone[0],
        gone[-1],
        len(gone),
    )
    assert spool.stats().damage_unacknowledged == 0
    spool.close()
    spool = Spool(tmp_path, OPTIONS).open()
    assert spool.stats().damage_unacknowledged == 0  # the acknowledgement survives a restart
    assert spool.damage()[0].acknowledged_ms is not None
    spool.close()


@pytest.mark.parametrize("how", ["zeroed", "emptied", "cut_at_a_frame", "cut_in_a_frame"])
def test_a_damaged_middle_segment_loses_exactly_its_records(
    tmp_path: Path, caplog: pytest.LogCaptureFixture, how: str
) -> None:
    segments = fill(tmp_path, 200)
    target = segments[1]
    held = seqs_of(target, segments[2], 200)
    size = target.stat().st_size
    kept = 10 if how.startswith("cut") else 0
    if how == "zeroed":
        target.write_bytes(b"\0" * size)
    elif how == "emptied":
        target.write_bytes(b"")
    else:
        cut = SEGMENT_HEADER_SIZE + kept * FRAME + (0 if how == "cut_at_a_frame" else 50)
        with target.open("r+b") as handle:
            handle.truncate(cut)
    lost = held[kept:]
    caplog.set_level(logging.ERROR)
    seqs, spool = reopen_and_read(tmp_path)
    assert seqs == [s for s in range(1, 201) if s not in lost]
    assert spool.stats().corrupt_skipped == len(lost)
    assert f"in {target} at offset" in caplog.text
    assert f"record(s) lost (seqs {lost[0]}..{lost[-1]})" in caplog.text
    assert sum(f.records for f in spool.damage()) == len(lost)
    spool.close()
    _seqs, spool = reopen_and_read(tmp_path)
    assert spool.stats().corrupt_skipped == 0  # found once, counted once
    spool.close()


def test_all_segments_deleted_with_the_ledger_kept_counts_every_unacked_record(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    segments = fill(tmp_path, 200, ack_first=30)
    for path in tmp_path.glob("*.seg"):
        path.unlink()
    caplog.set_level(logging.ERROR)
    seqs, spool = reopen_and_read(tmp_path)
    assert seqs == []
    assert spool.stats().lost_missing == 170  # the 30 acknowledged ones are in Kafka
    missing = [f for f in spool.damage() if f.reason == "segment_missing"]
    assert [f.file for f in missing] == [p.name for p in segments if int(p.name[:20]) + PER_SEGMENT - 1 > 30]
    assert missing[0].first_seq == 31
    assert missing[-1].last_seq == 200
    assert spool.append(RECORD) == 201  # seqs are never re-used
    spool.close()


def test_the_newest_segment_of_a_crashed_run_deleted_counts_what_was_synced(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    spool = Spool(tmp_path, OPTIONS).open()
    for _ in range(80):
        spool.append(RECORD)
    spool.flush()  # the ledger learns how far the active segment is on disk
    crash(spool)
    newest = sorted(tmp_path.glob("*.seg"))[-1]
    newest.unlink()
    caplog.set_level(logging.ERROR)
    seqs, spool = reopen_and_read(tmp_path)
    assert seqs == list(range(1, PER_SEGMENT + 1))
    assert spool.stats().lost_missing == 80 - PER_SEGMENT
    assert "after seq 80 in the last fsync interval before the unclean stop are not counted" in caplog.text
    spool.close()


def test_damage_left_in_a_kept_segment_is_known_at_the_next_open(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    (segment,) = fill(tmp_path, 30)
    data = bytearray(segment.read_bytes())
    data[SEGMENT_HEADER_SIZE + 10 * FRAME + HEADER_SIZE + 50] ^= 0x01  # seq 11
    segment.write_bytes(bytes(data))
    spool = Spool(tmp_path, OPTIONS).open()
    assert spool.stats().corrupt_skipped == 1
    spool.close()
    caplog.set_level(logging.INFO)
    caplog.clear()
    spool = Spool(tmp_path, OPTIONS).open()  # nothing acked: the segment and its damage stay
    assert spool.stats().corrupt_skipped == 0
    assert "known damage" in caplog.text
    assert not [r for r in caplog.records if r.levelno >= logging.ERROR and "corrupt data" in r.getMessage()]
    spool.close()


def test_damage_found_while_reading_is_reported(tmp_path: Path) -> None:
    spool = Spool(tmp_path, SpoolOptions(segment_bytes=8192, max_bytes=1 << 20, group_records=1)).open()
    spool.append_many([RECORD] * 5)
    spool._recent = type(spool._recent)(0)  # read from the file
    (segment,) = sorted(tmp_path.glob("*.seg"))
    with segment.open("r+b") as handle:  # the disk goes bad under the running spool
        handle.seek(SEGMENT_HEADER_SIZE + 2 * FRAME + HEADER_SIZE + 20)
        handle.write(b"\xff")
    seqs: list[int] = []
    while (batch := spool.read_unacked(100, 1 << 20)) is not None:
        seqs.extend(r.seq for r in batch.records)
        spool.ack(batch.first_seq)
    assert seqs == [1, 2, 4, 5]
    ((reason, first, last, records),) = [
        (f.reason, f.first_seq, f.last_seq, f.records) for f in spool.damage()
    ]
    assert (reason, first, last, records) == ("corrupt", 3, 3, 1)
    assert spool.stats().damage_unacknowledged == 1
    spool.close()


def _bad_byte_in_frame(segment: Path, index: int) -> None:
    with segment.open("r+b") as handle:
        handle.seek(SEGMENT_HEADER_SIZE + index * FRAME + HEADER_SIZE + 20)
        handle.write(b"\xff")


@pytest.mark.parametrize(("damaged", "left"), [((0,), [2, 3, 4, 5]), ((0, 1, 2, 3, 4), [])])
def test_a_batch_damaged_before_it_is_sent_again_goes_without_the_lost_records(
    tmp_path: Path, damaged: tuple[int, ...], left: list[int]
) -> None:
    """The disk went bad under a batch in flight; the uplink did not take it, so it is read
    again: what is left goes as a batch of its own (its seqs are the batch's), the rest counted."""
    spool = Spool(tmp_path, SpoolOptions(segment_bytes=8192, max_bytes=1 << 20, group_records=1)).open()
    spool.append_many([RECORD] * 5)
    spool._recent = type(spool._recent)(0)  # read from the file
    first = spool.read_unacked(100, 1 << 20)
    assert first is not None
    assert (first.first_seq, first.last_seq) == (1, 5)
    (segment,) = sorted(tmp_path.glob("*.seg"))
    for index in damaged:
        _bad_byte_in_frame(segment, index)
    assert spool.release(first.first_seq)
    again = spool.read_unacked(100, 1 << 20)
    if left:
        assert again is not None
        assert [r.seq for r in again.records] == left
        assert (again.first_seq, again.last_seq) == (left[0], left[-1])
        assert again.acked == left[0] - 1  # the lost seqs are settled: nothing waits for them
        assert spool.ack(again.first_seq)
    else:
        assert again is None
    stats = spool.stats()
    assert stats.corrupt_skipped == len(damaged)
    assert stats.acked == len(left)
    assert (stats.depth, stats.in_flight) == (0, 0)
    assert spool.read_unacked(100, 1 << 20) is None
    assert sum(f.records for f in spool.damage()) == len(damaged)
    spool.close()


def _five_in_two_batches(tmp_path: Path) -> tuple[Spool, Path]:
    spool = Spool(tmp_path, SpoolOptions(segment_bytes=8192, max_bytes=1 << 20, group_records=1)).open()
    spool.append_many([RECORD] * 6)
    spool._recent = type(spool._recent)(0)  # read from the file
    for first in (1, 4):
        batch = spool.read_unacked(3, 1 << 20)
        assert batch is not None
        assert batch.first_seq == first
    assert spool.release_all() == 2
    (segment,) = sorted(tmp_path.glob("*.seg"))
    return spool, segment


def test_a_released_batch_lost_whole_lets_the_next_released_one_go_first(tmp_path: Path) -> None:
    spool, segment = _five_in_two_batches(tmp_path)
    for index in (0, 1, 2):
        _bad_byte_in_frame(segment, index)
    again = spool.read_unacked(100, 1 << 20)
    assert again is not None
    assert [r.seq for r in again.records] == [4, 5, 6]  # not fresh records past a batch still due
    assert again.acked == 3
    assert spool.stats().corrupt_skipped == 3
    spool.close()


@pytest.mark.parametrize(("frames_left", "sent_again"), [(5, [[4, 5]]), (2, [])])
def test_a_segment_cut_short_under_released_batches_is_counted_not_waited_on(
    tmp_path: Path, frames_left: int, sent_again: list[list[int]]
) -> None:
    """The file lost its end while batches were in flight: what is left goes again, the rest is
    counted and reported with its seqs, and no read waits for bytes that will not come."""
    spool, segment = _five_in_two_batches(tmp_path)
    keep = SEGMENT_HEADER_SIZE + frames_left * FRAME
    with segment.open("r+b") as handle:
        handle.truncate(keep)
    batches = []
    while (batch := spool.read_unacked(100, 1 << 20)) is not None:
        batches.append([r.seq for r in batch.records])
        assert spool.ack(batch.first_seq)
    assert batches[0] == [1, 2, 3][:frames_left]
    assert batches[1:] == sent_again
    lost = 6 - frames_left
    assert spool.stats().corrupt_skipped == lost
    assert sum(f.records for f in spool.damage()) == lost
    named = {s for f in spool.damage() for s in range(f.first_seq or 0, (f.last_seq or -1) + 1)}
    assert named == set(range(frames_left + 1, 7))
    spool.close()
