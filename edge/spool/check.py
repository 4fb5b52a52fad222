"""Inspect a spool directory offline, read only: ``fleetlink spool check DIR``.

What a restart would find, without changing anything (no lock taken, no file written, no tail
truncated): each segment (file, first and last seq, records, bytes), the records held and how
many of them are not acknowledged, the ledger's state, every damage finding (``survey``) and the
findings of earlier opens still awaiting an operator (``damage.json``). The result is plain data
(JSON-ready); ``ok`` is false when there is damage an operator must look at.

``acknowledge_offline`` is the one write: it marks the findings of a stopped edge's spool
acknowledged (``fleetlink spool acknowledge DIR``).
"""

from __future__ import annotations

import fcntl
import os
from pathlib import Path
from typing import Any

from fleetlink.edge.errors import SpoolLockedError
from fleetlink.edge.spool.damage import REPORT_NAME, DamageReport, read_report
from fleetlink.edge.spool.frames import HEADER_SIZE, SEGMENT_HEADER_SIZE, Damage, scan
from fleetlink.edge.spool.ledger import read_ledger
from fleetlink.edge.spool.marks import SNAPSHOT_NAME, MarkBook, MarksError, decode_marks, read_snapshot
from fleetlink.edge.spool.segments import SEGMENT_NAME, Segment, survey

STREAM_DIRS = ("durable",)
"""Where an edge keeps its spool inside ``spool.dir`` (a check of ``spool.dir`` looks there)."""


def spool_directory(path: Path) -> Path:
    """``path``, or its ``durable`` stream when ``path`` is an edge's ``spool.dir``."""
    if (path / "ledger").exists() or any(SEGMENT_NAME.fullmatch(p.name) for p in _entries(path)):
        return path
    for name in STREAM_DIRS:
        if (path / name).is_dir():
            return path / name
    return path


def _entries(path: Path) -> list[Path]:
    try:
        return list(path.iterdir())
    except OSError:
        return []


def in_use(directory: Path) -> bool:
    """Whether a process holds the spool open (its ``LOCK`` is flocked)."""
    try:
        fd = os.open(directory / "LOCK", os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(fd)
    return False


def _unacked(segment: Segment, ack_mark: int, max_len: int) -> int:
    if segment.first_seq > ack_mark:
        return segment.count
    if segment.last_seq <= ack_mark:
        return 0
    data = segment.path.read_bytes()
    return sum(
        max(0, e.last_seq - max(e.seq - 1, ack_mark))
        for e in scan(data, SEGMENT_HEADER_SIZE, len(data), max_len=max_len, final=True, copy=False)
        if not isinstance(e, Damage)
    )


def check_spool(path: Path) -> dict[str, Any]:
    """Everything ``fleetlink spool check`` prints, for the spool at ``path``."""
    directory = spool_directory(path)
    if not directory.is_dir():
        return {"directory": str(directory), "ok": False, "error": "not a directory"}
    state = read_ledger(directory)
    files = [p for p in _entries(directory) if SEGMENT_NAME.fullmatch(p.name)]
    largest = max((p.stat().st_size for p in files), default=0)
    max_len = max(largest - SEGMENT_HEADER_SIZE - HEADER_SIZE, 1)  # no frame outgrows its file
    found = survey(directory, state, max_len)
    report = read_report(directory / REPORT_NAME)
    reported = {f.key: f for f in report}
    damage = []
    for finding in found.findings:
        known = reported.get(finding.key)
        entry = finding.as_dict()
        entry["needs_operator"] = finding.needs_operator
        entry["acknowledged_ms"] = known.acknowledged_ms if known is not None else None
        entry["found_ms"] = known.found_ms if known is not None else None
        damage.append(entry)
    waiting = [f.as_dict() for f in report if f.needs_operator and f.acknowledged_ms is None]
    segments = []
    for scanned in found.scans:
        segment = scanned.segment
        segments.append(
            {
                "file": segment.path.name,
                "first_seq": segment.first_seq,
                "last_seq": segment.last_seq if segment.count else None,
                "records": segment.count,
                "unacknowledged": _unacked(segment, state.ack_mark, max_len),
                "bytes": segment.path.stat().st_size,
                "damaged_ranges": len(scanned.findings),
            }
        )
    snapshot = read_snapshot(directory / SNAPSHOT_NAME)
    marks = MarkBook()
    marks.update(snapshot or ())
    for scanned in found.scans:
        for block in scanned.marks:
            try:
                marks.update(decode_marks(block))
            except MarksError:
                continue
    new_damage = any(d["needs_operator"] and d["acknowledged_ms"] is None for d in damage)
    return {
        "directory": str(directory),
        "in_use": in_use(directory),
        "ledger": {
            "ack_mark": state.ack_mark,
            "reserved": state.reserved,
            "clean_stop": state.clean_next_seq is not None,
            "next_seq": state.clean_next_seq,
            "files_missing": list(state.missing)
            or (["ledger", "ledger.copy"] if state.fresh and files else []),
            "segment_table": state.tracked,
        },
        "segments": segments,
        "records": sum(s["records"] for s in segments),
        "unacknowledged": sum(s["unacknowledged"] for s in segments),
        "bytes": sum(s["bytes"] for s in segments),
        "damage": damage,
        "records_lost": sum(d["records"] for d in damage),
        "awaiting_acknowledgement": waiting,
        "publishers_marked": len(marks),
        "marks_snapshot_damaged": snapshot is None,
        "ok": not new_damage and not waiting,
    }


def acknowledge_offline(path: Path, now_ms: int) -> list[dict[str, Any]]:
    """Acknowledge the damage findings of a spool no process holds open (its ``LOCK`` is taken
    while the report is rewritten); raises ``SpoolLockedError`` when one does."""
    directory = spool_directory(path)
    fd = os.open(directory / "LOCK", os.O_RDWR | os.O_CREAT, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise SpoolLockedError(
                "the spool is open by a running edge: acknowledge through its admin API "
                "(POST /spool/damage/acknowledge, or fleetlink spool acknowledge --admin URL)",
                path=directory,
            ) from None
        return [f.as_dict() for f in DamageReport(directory).load().acknowledge(now_ms)]
    finally:
        os.close(fd)
