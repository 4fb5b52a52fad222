"""Reopening a damaged spool: torn tails, flipped bits, bad headers, torn ledgers."""

from __future__ import annotations

import logging
from pathlib import Path

import pytest

from fleetlink.edge.spool import Spool
from fleetlink.edge.spool.frames import HEADER_SIZE, SEGMENT_HEADER_SIZE
from fleetlink.edge.spool.ledger import ENTRY_SIZE
from tests.unit.edge.spool.one_record_frames import (
    FRAME,
    OPTIONS,
    RECORD,
    fill,
    reopen_and_read,
)


def test_a_cut_last_record_is_truncated_counted_exactly_and_logged(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    (segment,) = fill(tmp_path, 20)
    size = segment.stat().st_size
    with segment.open("r+b") as handle:
        handle.truncate(size - 40)  # the last frame loses its end
    caplog.set_level(logging.ERROR)
    seqs, spool = reopen_and_read(tmp_path)
    assert seqs == list(range(1, 20))
    offset = SEGMENT_HEADER_SIZE + 19 * FRAME
    assert f"segment cut short in {segment} at offset {offset}" in caplog.text
    assert "1 record(s) lost (seqs 20..20)" in caplog.text  # the ledger knew seq 20 was in it
    assert spool.stats().corrupt_skipped == 1
    assert spool.stats().damage_unacknowledged == 1
    assert spool.append(RECORD) is not None
    spool.close()
    assert segment.exists() is False or segment.stat().st_size == offset  # truncated, then acked away


def test_a_torn_write_beyond_the_last_known_record_is_a_crash_trace(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    (segment,) = fill(tmp_path, 20)
    size = segment.stat().st_size
    whole = segment.read_bytes()[-FRAME:]
    torn = bytearray(whole[:60])
    torn[8:16] = (21).to_bytes(8, "little")  # the header of seq 21, whose write was cut short
    with segment.open("ab") as handle:
        handle.write(bytes(torn))
    caplog.set_level(logging.WARNING)
    seqs, spool = reopen_and_read(tmp_path)
    assert seqs == list(range(1, 21))
    assert f"torn tail in {segment} at offset {size}" in caplog.text
    assert "a write a crash cut short" in caplog.text
    stats = spool.stats()
    assert stats.corrupt_skipped == 1
    assert stats.damage_unacknowledged == 0  # never taken: nothing for an operator to look at
    spool.close()


def test_flipped_bit_in_the_middle_loses_one_record_counted(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    (segment,) = fill(tmp_path, 30)
    data = bytearray(segment.read_bytes())
    offset = SEGMENT_HEADER_SIZE + 10 * FRAME
    data[offset + HEADER_SIZE + 50] ^= 0x01  # a payload bit of seq 11
    segment.write_bytes(bytes(data))
    caplog.set_level(logging.ERROR)
    seqs, spool = reopen_and_read(tmp_path)
    assert seqs == [s for s in range(1, 31) if s != 11]
    assert f"corrupt data in {segment} at offset {offset} ({FRAME} bytes: checksum mismatch)" in caplog.text
    assert "1 record(s) lost (seqs 11..11)" in caplog.text
    assert spool.stats().corrupt_skipped == 1
    spool.close()


def test_a_smashed_run_counts_the_seq_gap(tmp_path: Path) -> None:
    (segment,) = fill(tmp_path, 30)
    data = bytearray(segment.read_bytes())
    start = SEGMENT_HEADER_SIZE + 5 * FRAME
    data[start : start + 4 * FRAME] = b"\x00" * (4 * FRAME)  # seqs 6..9 wiped
    segment.write_bytes(bytes(data))
    seqs, spool = reopen_and_read(tmp_path)
    assert seqs == [s for s in range(1, 31) if not 6 <= s <= 9]
    assert spool.stats().corrupt_skipped == 4
    spool.close()


def test_damage_in_an_older_segment_is_skipped_not_truncated(tmp_path: Path) -> None:
    segments = fill(tmp_path, 200)
    assert len(segments) >= 3
    first = segments[0]
    data = bytearray(first.read_bytes())
    data[-10] ^= 0xFF  # the last frame of a sealed segment
    first.write_bytes(bytes(data))
    size = first.stat().st_size
    seqs, spool = reopen_and_read(tmp_path)
    lost = (size - SEGMENT_HEADER_SIZE) // FRAME  # the seq of the first segment's last frame
    assert lost * FRAME + SEGMENT_HEADER_SIZE == size
    assert seqs == [s for s in range(1, 201) if s != lost]
    assert spool.stats().corrupt_skipped == 1
    spool.close()


def test_bad_segment_header_is_logged_but_frames_still_read(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    (segment,) = fill(tmp_path, 5)
    data = bytearray(segment.read_bytes())
    data[0:8] = b"XXXXXXXX"
    segment.write_bytes(bytes(data))
    caplog.set_level(logging.ERROR)
    seqs, spool = reopen_and_read(tmp_path)
    assert seqs == [1, 2, 3, 4, 5]
    assert f"corrupt data in {segment} at offset 0" in caplog.text
    assert spool.stats().corrupt_skipped == 0  # no record was lost
    spool.close()


def test_empty_and_header_only_files_are_removed(tmp_path: Path) -> None:
    fill(tmp_path, 3)
    (tmp_path / f"{100:020d}.seg").write_bytes(b"")
    (tmp_path / f"{200:020d}.seg").write_bytes(b"FLSPOOL1" + (200).to_bytes(8, "little"))
    seqs, spool = reopen_and_read(tmp_path)
    assert seqs == [1, 2, 3]
    assert not (tmp_path / f"{100:020d}.seg").exists()
    assert not (tmp_path / f"{200:020d}.seg").exists()
    spool.close()


def test_acked_segments_are_removed_at_open(tmp_path: Path) -> None:
    first = fill(tmp_path, 200)[0]
    saved = first.read_bytes()
    with Spool(tmp_path, OPTIONS) as spool:
        batch = spool.read_unacked(120, 1 << 20)
        assert batch is not None
        assert batch.last_seq < 120  # the first segment ends before 120
        spool.ack(batch.first_seq)
        assert not first.exists()  # deleted once every record in it is acked
    first.write_bytes(saved)  # as if the deletion had not reached the disk before a power cut
    seqs, spool = reopen_and_read(tmp_path)
    assert not first.exists()
    assert seqs == list(range(batch.last_seq + 1, 201))
    spool.close()


def test_torn_ledger_entry_is_ignored(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    fill(tmp_path, 50, ack_first=20)
    ledger = tmp_path / "ledger"
    data = ledger.read_bytes()
    ledger.write_bytes(data + b"\x01\x00\x00")  # half an entry, as a crash mid-write leaves it
    caplog.set_level(logging.WARNING)
    seqs, spool = reopen_and_read(tmp_path)
    assert seqs == list(range(21, 51))
    assert f"spool ledger {ledger}: entry at offset {len(data)} fails its checksum" in caplog.text
    spool.close()
    assert len(ledger.read_bytes()) % ENTRY_SIZE == 0  # rewritten whole


def test_a_lost_ledger_file_is_restored_from_its_copy(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    fill(tmp_path, 50, ack_first=20)
    (tmp_path / "ledger").unlink()
    caplog.set_level(logging.ERROR)
    seqs, spool = reopen_and_read(tmp_path)
    assert seqs == list(range(21, 51))  # the copy knew the ack mark: nothing is sent twice
    assert f"ledger file {tmp_path / 'ledger'} is missing" in caplog.text
    assert spool.stats().damage_unacknowledged == 1
    assert spool.append(RECORD) == 51
    spool.close()
    assert (tmp_path / "ledger").stat().st_size > 0  # written again


def test_both_ledger_files_lost_means_resend_not_loss(tmp_path: Path) -> None:
    fill(tmp_path, 50, ack_first=20)
    (tmp_path / "ledger").unlink()
    (tmp_path / "ledger.copy").unlink()
    seqs, spool = reopen_and_read(tmp_path)
    assert seqs == list(range(1, 51))  # acked records are sent again: duplicates, never a loss
    assert [f.reason for f in spool.damage()] == ["ledger_missing"]
    assert spool.append(RECORD) == 51
    spool.close()


def test_the_origin_lives_as_long_as_the_spool(tmp_path: Path) -> None:
    """An exactly-once uplink writes each seq of an origin once: the origin must outlive restarts
    and the loss of one ledger file, and change when the spool starts its seqs again."""
    fill(tmp_path, 10)
    with Spool(tmp_path, OPTIONS) as spool:
        origin = spool.origin
    assert origin != 0
    (tmp_path / "ledger").unlink()
    with Spool(tmp_path, OPTIONS) as spool:
        assert spool.origin == origin
    (tmp_path / "ledger").unlink()
    (tmp_path / "ledger.copy").unlink()
    with Spool(tmp_path, OPTIONS) as spool:
        assert spool.origin not in (0, origin)  # the seqs may repeat: a new origin
    fresh = tmp_path / "other"
    with Spool(fresh, OPTIONS) as spool:
        assert spool.origin not in (0, origin)
