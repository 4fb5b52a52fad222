"""Damage found in a spool directory, and the report that keeps it until an operator looks.

A ``Finding`` says what was found (``reason``), where (file, byte range), which records it cost
(seq range, count) and why. Recovery makes them (``segments.survey``); the spool logs and counts
the new ones and keeps them in ``damage.json`` beside the segments, so that

- damage still on disk (a corrupt range in a segment that is kept) is counted once, not again at
  every open (a finding is known by file, offset and reason);
- the edge reports itself ``degraded`` until an operator acknowledged every finding (admin API
  ``POST /spool/damage/acknowledge``, ``fleetlink spool acknowledge``), across restarts.

Reasons: ``corrupt`` (a range of a segment holds no valid frame), ``truncated`` (a segment ends
before the last record the ledger knew it held), ``segment_missing`` (a segment file the ledger
knew is gone), ``ledger_missing`` (a ledger file is gone; nothing lost with one copy left),
``torn_tail`` (a frame cut short at the end of the newest segment by a crash: its records had not
been taken; counted, logged, but not damage an operator must acknowledge).
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import time
from collections.abc import Iterable, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

log = logging.getLogger(__name__)

REPORT_NAME = "damage.json"
MAX_FINDINGS = 1000
"""Findings kept in the report (the oldest acknowledged ones go first)."""
QUIET_REASONS = frozenset({"torn_tail"})
"""Counted and logged, but no operator needs to acknowledge them (the normal trace of a crash)."""


@dataclass(frozen=True, slots=True)
class Finding:
    """One piece of damage: what was found, where, and which records it cost."""

    reason: str
    file: str
    """The file's name in the spool directory."""
    offset: int
    end: int
    """The damaged byte range ``[offset, end)`` (a whole file: ``0`` .. its size, or ``0, 0``)."""
    first_seq: int | None
    last_seq: int | None
    """The seqs lost (``None``: none, or not known)."""
    records: int
    """Records lost (not yet acknowledged by Kafka when the damage was found)."""
    detail: str
    found_ms: int = 0
    acknowledged_ms: int | None = None

    @property
    def key(self) -> tuple[str, int, str]:
        """What identifies the finding across opens: ``(file, offset, reason)``."""
        return (self.file, self.offset, self.reason)

    @property
    def needs_operator(self) -> bool:
        """Whether an operator must acknowledge it (a torn tail after a crash needs none)."""
        return self.reason not in QUIET_REASONS

    def seqs(self) -> str:
        """The seqs lost as text for a log line (``seqs 5..9``, or ``no seqs``)."""
        if self.first_seq is None or self.last_seq is None:
            return "no seqs"
        return f"seqs {self.first_seq}..{self.last_seq}"

    def as_dict(self) -> dict[str, Any]:
        """The finding as a JSON-ready dict (the form of ``damage.json``)."""
        return asdict(self)


def lost_range(lo: int, hi: int, ack_mark: int) -> tuple[int | None, int | None, int]:
    """The seqs ``lo..hi`` above ``ack_mark`` (those below are in Kafka): ``(first, last, n)``."""
    lo = max(lo, ack_mark + 1)
    if hi < lo:
        return None, None, 0
    return lo, hi, hi - lo + 1


def _finding(data: Any) -> Finding | None:
    if not isinstance(data, dict):
        return None
    try:
        return Finding(
            reason=str(data["reason"]),
            file=str(data["file"]),
            offset=int(data["offset"]),
            end=int(data["end"]),
            first_seq=None if data.get("first_seq") is None else int(data["first_seq"]),
            last_seq=None if data.get("last_seq") is None else int(data["last_seq"]),
            records=int(data["records"]),
            detail=str(data.get("detail", "")),
            found_ms=int(data.get("found_ms", 0)),
            acknowledged_ms=None if data.get("acknowledged_ms") is None else int(data["acknowledged_ms"]),
        )
    except (KeyError, TypeError, ValueError):
        return None


def read_report(path: Path) -> list[Finding]:
    """The findings in a report file (``[]`` when there is none; unreadable entries skipped)."""
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return []
    except (OSError, ValueError) as exc:
        log.warning("spool damage report %s cannot be read (%s); starting a new one", path, exc)
        return []
    entries = data.get("findings") if isinstance(data, dict) else None
    return [f for f in map(_finding, entries if isinstance(entries, list) else []) if f is not None]


def write_report(path: Path, findings: Sequence[Finding]) -> None:
    """Replace the report atomically (temp file, fsync, rename)."""
    tmp = path.with_name(path.name + ".tmp")
    body = json.dumps({"findings": [f.as_dict() for f in findings]}, indent=1, sort_keys=True)
    with open(tmp, "w", encoding="utf-8") as handle:
        handle.write(body + "\n")
        handle.flush()
        os.fsync(handle.fileno())
    os.replace(tmp, path)


def wall_ms() -> int:
    """The wall clock in milliseconds since the epoch."""
    return time.time_ns() // 1_000_000


class DamageReport:
    """The findings of one spool directory (``damage.json``). Not thread-safe: the spool's lock."""

    def __init__(self, directory: Path) -> None:
        self.path = directory / REPORT_NAME
        self._findings: list[Finding] = []
        self.write_errors = 0

    def load(self) -> DamageReport:
        """Read the findings from ``damage.json`` (none when it is absent or unreadable); returns ``self``."""
        self._findings = read_report(self.path)
        return self

    @property
    def findings(self) -> tuple[Finding, ...]:
        """Every finding kept, acknowledged or not."""
        return tuple(self._findings)

    def unacknowledged(self) -> tuple[Finding, ...]:
        """The findings that still await an operator's acknowledgement."""
        return tuple(f for f in self._findings if f.needs_operator and f.acknowledged_ms is None)

    def add(self, found: Iterable[Finding], now_ms: int) -> list[Finding]:
        """Record ``found``; returns the new ones (not known by key), stamped ``now_ms``."""
        known = {f.key for f in self._findings}
        new = [replace(f, found_ms=now_ms) for f in found if f.key not in known]
        if new:
            self._findings.extend(new)
            self._prune()
            self._save()
        return new

    def acknowledge(self, now_ms: int) -> list[Finding]:
        """Mark every unacknowledged finding acknowledged; returns them."""
        done = list(self.unacknowledged())
        if done:
            self._findings = [
                replace(f, acknowledged_ms=now_ms) if f.needs_operator and f.acknowledged_ms is None else f
                for f in self._findings
            ]
            self._prune()
            self._save()
        return done

    def _prune(self) -> None:
        excess = len(self._findings) - MAX_FINDINGS
        if excess <= 0:
            return
        done = [
            i for i, f in enumerate(self._findings) if not f.needs_operator or f.acknowledged_ms is not None
        ]
        drop = set(done[:excess])
        self._findings = [f for i, f in enumerate(self._findings) if i not in drop]

    def _save(self) -> None:
        try:
            write_report(self.path, self._findings)
        except OSError as exc:
            self.write_errors += 1
            with contextlib.suppress(OSError):
                self.path.with_name(self.path.name + ".tmp").unlink()
            log.error("spool damage report %s cannot be written: %s (kept in memory)", self.path, exc)
