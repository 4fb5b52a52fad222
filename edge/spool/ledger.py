"""The spool's ledger: append-only files of checksummed 16-byte entries, kept twice.

Entries: ``kind u8 | 3 zero bytes | value u64 | crc u32`` (CRC-32 of the first 12 bytes).

- ``ACK`` value = the ack mark: every seq <= it is acknowledged (or gone).
- ``RESERVE`` value = an exclusive bound on the seqs this spool may have handed out; written
  and fsynced before any seq reaches it, so a restart after power loss never re-uses a seq
  that might already be in Kafka.
- ``CLEAN`` value = the next seq, written last by a clean ``close()``.
- ``SEGMENT`` value = the first seq of a segment just created (fsynced before it holds records).
- ``EXTENT`` value = the last seq the newest ``SEGMENT`` holds as far as it was fsynced
  (written after each fsync of the active segment and when it is sealed).
- ``GONE`` value = the first seq of a segment deleted on purpose (acknowledged or evicted).
- ``ORIGIN`` value = the spool's origin: a random non-zero 64-bit id made when the spool is new
  and kept for its life. An exactly-once uplink writes each seq of one origin once; a spool made
  anew (its seqs start again) gets a new origin, so its records are not taken for duplicates.

``SEGMENT``/``EXTENT``/``GONE`` are the segment table: what the segment files hold, so a
segment that disappears, or holds less than it did, is found and its records counted exactly.

Every entry goes to two files, ``ledger`` and ``ledger.copy``: losing one (deleted, emptied)
loses nothing; opening reads both and merges them (the highest ack mark and reservation, the
union of the segment tables). Reading a file stops at the first entry that fails its checksum
(a torn tail): never a half-written ledger. At open both files are rewritten (temp file, fsync,
rename, fsync of the directory) with just the current state, and again whenever they grow past
``COMPACT_BYTES``.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import os
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path

log = logging.getLogger(__name__)

_BODY = struct.Struct("<B3xQ")
ENTRY_SIZE = _BODY.size + 4
ACK, RESERVE, CLEAN, SEGMENT, EXTENT, GONE, ORIGIN = 1, 2, 3, 4, 5, 6, 7
KINDS = frozenset({ACK, RESERVE, CLEAN, SEGMENT, EXTENT, GONE, ORIGIN})
COMPACT_BYTES = 64 * 1024
SPACE_ERRORS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG})
LEDGER_NAME = "ledger"
COPY_NAME = "ledger.copy"


def encode_entry(kind: int, value: int) -> bytes:
    """One 16-byte ledger entry: ``kind``, ``value`` and the CRC-32 of both."""
    body = _BODY.pack(kind, value)
    return body + zlib.crc32(body).to_bytes(4, "little")


@dataclass(slots=True)
class LedgerState:
    """What one ledger file (or both, merged) says: marks, the segment table, how the spool stopped."""

    ack_mark: int = 0
    reserved: int = 1
    clean_next_seq: int | None = None
    """Set when the last entry was a clean close: the spool stopped in order."""
    damaged_at: int | None = None
    """Offset of the first entry that failed its checksum, if any."""
    fresh: bool = False
    """There was no ledger: a new spool (or a lost one: see ``missing``)."""
    segments: dict[int, int | None] = field(default_factory=dict)
    """The segment table: first seq -> the last seq known to be in it (``None``: none yet)."""
    gone: set[int] = field(default_factory=set)
    """Segments deleted on purpose since the ledger was last rewritten."""
    tracked: bool = False
    """The ledger keeps a segment table (written by this version: a ``SEGMENT`` entry seen)."""
    missing: tuple[str, ...] = ()
    """Ledger files that were absent or empty while the other one had entries."""
    origin: int = 0
    """The spool's origin (0: the ledger has none yet: a new spool, or one written before)."""


def parse_ledger(data: bytes) -> LedgerState:
    """The state the entries of one ledger file describe; reading stops at the first damaged or unknown
    entry (``damaged_at``)."""
    state = LedgerState(fresh=not data)
    newest: int | None = None
    for off in range(0, len(data), ENTRY_SIZE):
        entry = data[off : off + ENTRY_SIZE]
        body = entry[: _BODY.size]
        if len(entry) < ENTRY_SIZE or zlib.crc32(body) != int.from_bytes(entry[_BODY.size :], "little"):
            state.damaged_at = off
            break
        kind, value = _BODY.unpack(body)
        if kind not in KINDS:
            state.damaged_at = off
            break
        state.clean_next_seq = value if kind == CLEAN else None
        if kind == ACK:
            state.ack_mark = max(state.ack_mark, value)
        elif kind == RESERVE:
            state.reserved = max(state.reserved, value)
        elif kind == SEGMENT:
            state.tracked = True
            state.segments.setdefault(value, None)
            newest = value
        elif kind == EXTENT and newest is not None and newest in state.segments:
            known = state.segments[newest]
            state.segments[newest] = value if known is None else max(known, value)
        elif kind == GONE:
            state.segments.pop(value, None)
            state.gone.add(value)
        elif kind == ORIGIN and value:
            state.origin = value
    return state


def merge_states(first: LedgerState, second: LedgerState) -> LedgerState:
    """One state from the two copies: the highest marks, the union of the segment tables (a
    segment gone in either is gone), clean only when both say so."""
    if first.fresh:
        return second
    if second.fresh:
        return first
    gone = first.gone | second.gone
    segments = dict(first.segments)
    for seq, extent in second.segments.items():
        known = segments.get(seq)
        segments[seq] = extent if known is None else known if extent is None else max(known, extent)
    for seq in gone:
        segments.pop(seq, None)
    clean = first.clean_next_seq if first.clean_next_seq == second.clean_next_seq else None
    return LedgerState(
        ack_mark=max(first.ack_mark, second.ack_mark),
        reserved=max(first.reserved, second.reserved),
        clean_next_seq=clean,
        damaged_at=first.damaged_at if first.damaged_at is not None else second.damaged_at,
        segments=dict(sorted(segments.items())),
        gone=gone,
        tracked=first.tracked or second.tracked,
        origin=first.origin or second.origin,
    )


def new_origin() -> int:
    """A random non-zero 64-bit spool origin."""
    return int.from_bytes(os.urandom(8), "little") or 1


def fsync_dir(path: Path) -> None:
    """fsync the directory ``path`` so that files created, renamed or deleted in it are durable."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def read_ledger(directory: Path) -> LedgerState:
    """Both copies of a directory's ledger, merged (read only: for ``Ledger.open`` and offline
    checks). ``missing`` names a copy that is absent or empty while the other has entries."""
    states: list[LedgerState] = []
    for name in (LEDGER_NAME, COPY_NAME):
        path = directory / name
        try:
            data = path.read_bytes()
        except FileNotFoundError:
            data = b""
        state = parse_ledger(data)
        if state.damaged_at is not None:
            log.warning(
                "spool ledger %s: entry at offset %d fails its checksum; %d trailing bytes ignored",
                path,
                state.damaged_at,
                len(data) - state.damaged_at,
            )
        states.append(state)
    merged = merge_states(states[0], states[1])
    if not merged.fresh:
        merged.missing = tuple(
            name for name, state in zip((LEDGER_NAME, COPY_NAME), states, strict=True) if state.fresh
        )
    return merged


class _LogFile:
    """One of the two ledger files: its descriptor and size. A failed append is truncated away;
    if even that fails, the next append rewrites the whole file instead."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.fd = -1
        self.size = 0
        self.needs_rewrite = False
        self.dirty = False

    def rewrite(self, data: bytes) -> None:
        """Replace the file by ``data``, atomically; raises ``OSError``."""
        tmp = self.path.with_name(self.path.name + ".tmp")
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            try:
                if os.write(fd, data) != len(data):
                    raise OSError(errno.ENOSPC, "short write")
                os.fsync(fd)
            finally:
                os.close(fd)
            os.replace(tmp, self.path)
        except OSError:
            with contextlib.suppress(OSError):
                tmp.unlink()
            raise
        self.close()
        self.fd = os.open(self.path, os.O_WRONLY | os.O_APPEND)
        self.size = len(data)
        self.needs_rewrite = False
        self.dirty = False

    def append(self, entry: bytes) -> bool:
        try:
            written = os.write(self.fd, entry)
        except OSError as exc:
            if exc.errno not in SPACE_ERRORS:
                raise
            written = -1
        if written != len(entry):
            try:
                os.ftruncate(self.fd, self.size)
            except OSError:
                self.needs_rewrite = True  # a partial entry may remain: replace the file next time
            return False
        self.size += len(entry)
        self.dirty = True
        return True

    def sync(self) -> None:
        if self.dirty and self.fd >= 0:
            os.fsync(self.fd)
            self.dirty = False

    def close(self) -> None:
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1


class Ledger:
    """The ledger files of one spool directory. Not thread-safe: the spool holds its lock."""

    def __init__(self, directory: Path) -> None:
        self.directory = directory
        self.path = directory / LEDGER_NAME
        self._files = (_LogFile(self.path), _LogFile(directory / COPY_NAME))
        self._ack_mark = 0
        self._reserved = 1
        self._segments: dict[int, int | None] = {}
        self._newest: int | None = None
        self.origin = 0
        """The spool's origin (``ORIGIN``), set by ``open``."""
        self.failures = 0

    def read(self) -> LedgerState:
        """Both files merged, without changing anything (``open`` rewrites them after)."""
        for log_file in self._files:
            log_file.path.with_name(log_file.path.name + ".tmp").unlink(missing_ok=True)
        return read_ledger(self.directory)

    def open(self, state: LedgerState, segments: dict[int, int | None]) -> None:
        """Start from ``state`` with the segment table ``segments`` (what recovery kept):
        both files are rewritten with it. Raises ``OSError`` when that fails."""
        self._ack_mark, self._reserved = state.ack_mark, state.reserved
        self.origin = state.origin or new_origin()
        self._segments = dict(segments)
        self._newest = max(self._segments, default=None)
        data = self._state_bytes()
        for log_file in self._files:
            log_file.rewrite(data)
        fsync_dir(self.directory)

    @property
    def segments(self) -> dict[int, int | None]:
        """A copy of the segment table: first seq -> the last seq known to be in it (``None``: none yet)."""
        return dict(self._segments)

    def _state_bytes(self) -> bytes:
        parts = [
            encode_entry(ORIGIN, self.origin),
            encode_entry(ACK, self._ack_mark),
            encode_entry(RESERVE, self._reserved),
        ]
        for first, extent in sorted(self._segments.items()):
            parts.append(encode_entry(SEGMENT, first))
            if extent is not None:
                parts.append(encode_entry(EXTENT, extent))
        return b"".join(parts)

    def _compact(self) -> bool:
        data = self._state_bytes()
        ok = True
        for log_file in self._files:
            try:
                log_file.rewrite(data)
            except OSError:
                ok = False
                self.failures += 1
                log.warning(
                    "spool ledger %s: rewrite failed; keeping the old file", log_file.path, exc_info=True
                )
        if ok:
            with contextlib.suppress(OSError):
                fsync_dir(self.directory)
        return ok

    def _append(self, kind: int, value: int, *, sync: bool) -> bool:
        files = self._files
        if any(f.needs_rewrite or f.size >= COMPACT_BYTES for f in files):
            return self._compact() and (not sync or self.sync())
        entry = encode_entry(kind, value)
        ok = True
        for log_file in files:
            if not log_file.append(entry):
                ok = False
                self.failures += 1
                if self.failures == 1 or self.failures % 1000 == 0:  # a full disk must not flood the log
                    log.warning(
                        "spool ledger %s: could not append an entry (disk full?); %d failures so far",
                        log_file.path,
                        self.failures,
                    )
        return ok and (not sync or self.sync())

    def record_ack(self, mark: int, *, sync: bool) -> bool:
        """Raise the ack mark to ``mark`` (every seq up to it is acknowledged) and append it; fsynced when
        ``sync``. Returns False when a file could not take it."""
        self._ack_mark = max(self._ack_mark, mark)
        return self._append(ACK, self._ack_mark, sync=sync)

    def record_reserve(self, bound: int) -> bool:
        """Always synced: the bound must be durable before seqs below it are used."""
        self._reserved = max(self._reserved, bound)
        return self._append(RESERVE, self._reserved, sync=True)

    def record_clean(self, next_seq: int) -> bool:
        """Append the mark of a clean close (``next_seq``: the seq to use next), fsynced; False on failure."""
        return self._append(CLEAN, next_seq, sync=True)

    def record_segment(self, first_seq: int) -> bool:
        """A segment was created (synced: the table must know it before it holds records)."""
        self._segments[first_seq] = None
        self._newest = first_seq
        return self._append(SEGMENT, first_seq, sync=True)

    def record_extent(self, first_seq: int, last_seq: int, *, sync: bool = False) -> bool:
        """Segment ``first_seq`` (the newest) holds records up to ``last_seq`` on disk."""
        if first_seq != self._newest or first_seq not in self._segments:
            return True
        known = self._segments[first_seq]
        if known is not None and known >= last_seq:
            return True
        self._segments[first_seq] = last_seq
        return self._append(EXTENT, last_seq, sync=sync)

    def record_gone(self, first_seq: int) -> bool:
        """Segment ``first_seq`` is deleted on purpose (synced before the file goes)."""
        self._segments.pop(first_seq, None)
        return self._append(GONE, first_seq, sync=True)

    def sync(self) -> bool:
        """fsync the ledger files if anything was appended since the last sync."""
        ok = True
        for log_file in self._files:
            if log_file.fd < 0:
                ok = False
                continue
            try:
                log_file.sync()
            except OSError:
                ok = False
                self.failures += 1
                log.warning("spool ledger %s: fsync failed", log_file.path, exc_info=True)
        return ok

    def close(self) -> None:
        """Close both ledger files."""
        for log_file in self._files:
            log_file.close()
