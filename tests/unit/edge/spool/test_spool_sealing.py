"""Sealing a segment under the ``interval`` policy: its unsynced rest goes to disk on the fsync
thread, never on the appending one; the ledger knows its last record before the next segment
takes one, so a power cut that loses that rest is counted."""

from __future__ import annotations

import dataclasses
import logging
import os
import shutil
from pathlib import Path

import pytest

from fleetlink.edge.spool import Spool
from fleetlink.edge.spool.frames import SEGMENT_HEADER_SIZE
from fleetlink.edge.spool.spool import MAX_SEALING
from tests.unit.edge.spool.one_record_frames import FRAME, OPTIONS, RECORD, reopen_and_read

NEVER = dataclasses.replace(OPTIONS, fsync_interval_ms=3_600_000)
"""The fsync thread waits an hour: only what the test calls happens."""


def open_paths() -> set[str]:
    """The files this process holds open."""
    out = set()
    for fd in os.listdir("/proc/self/fd"):
        try:
            out.add(os.readlink(f"/proc/self/fd/{fd}"))
        except OSError:  # closed meanwhile (the listing's own descriptor)
            continue
    return out


def test_a_sealed_segment_waits_for_the_fsync_thread(tmp_path: Path) -> None:
    spool = Spool(tmp_path, NEVER).open()
    try:
        for _ in range(200):
            spool.append(RECORD)
        segments = sorted(tmp_path.glob("*.seg"))
        assert len(segments) >= 3
        sealed = {str(p) for p in segments[:-1]}
        assert sealed <= open_paths()  # kept open, unsynced: the appends did not wait for the disk
        before = spool.stats().fsyncs
        spool.flush()
        assert not sealed & open_paths()
        assert spool.stats().fsyncs == before + len(sealed) + 1  # each sealed one, and the active one
    finally:
        spool.close()


def test_batch_and_always_seal_at_once(tmp_path: Path) -> None:
    for policy in ("batch", "always"):
        directory = tmp_path / policy
        spool = Spool(directory, dataclasses.replace(NEVER, fsync=policy, fsync_batch=10_000)).open()
        try:
            for _ in range(200):
                spool.append(RECORD)
            sealed = {str(p) for p in sorted(directory.glob("*.seg"))[:-1]}
            assert sealed
            assert not sealed & open_paths()
        finally:
            spool.close()


def test_closing_syncs_what_was_sealed(tmp_path: Path) -> None:
    spool = Spool(tmp_path, NEVER).open()
    for _ in range(200):
        spool.append(RECORD)
    spool.close()
    assert not {str(p) for p in tmp_path.glob("*.seg")} & open_paths()
    seqs, again = reopen_and_read(tmp_path)
    assert seqs == list(range(1, 201))
    assert again.stats().corrupt_skipped == 0
    again.close()


def test_a_power_cut_losing_a_sealed_rest_is_counted(
    tmp_path: Path, caplog: pytest.LogCaptureFixture
) -> None:
    live, cut = tmp_path / "live", tmp_path / "cut"
    spool = Spool(live, NEVER).open()
    try:
        for _ in range(200):
            spool.append(RECORD)
        # the disk as a power cut leaves it: the files as written, then the sealed segment's
        # unsynced rest (its last three records) gone
        shutil.copytree(live, cut)
    finally:
        spool.close()
    segments = sorted(cut.glob("*.seg"))
    sealed = segments[-2]
    last = int(segments[-1].name[:20]) - 1  # the sealed segment's last seq
    assert (sealed.stat().st_size - SEGMENT_HEADER_SIZE) % FRAME == 0
    with sealed.open("r+b") as handle:
        handle.truncate(sealed.stat().st_size - 3 * FRAME)
    caplog.set_level(logging.ERROR)
    seqs, again = reopen_and_read(cut)
    lost = {last - 2, last - 1, last}
    assert seqs == [s for s in range(1, 201) if s not in lost]
    assert f"3 record(s) lost (seqs {last - 2}..{last})" in caplog.text
    assert again.stats().damage_unacknowledged == 1
    again.close()


def test_the_segments_waiting_for_the_fsync_thread_are_bounded(tmp_path: Path) -> None:
    spool = Spool(tmp_path, NEVER).open()
    try:
        for _ in range(60 * (MAX_SEALING + 4)):
            spool.append(RECORD)
        segments = sorted(tmp_path.glob("*.seg"))
        assert len(segments) > MAX_SEALING + 2
        held = {str(p) for p in segments[:-1]} & open_paths()
        assert 0 < len(held) <= MAX_SEALING
    finally:
        spool.close()
