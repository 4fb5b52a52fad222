"""The spool's ledger: an append-only file of checksummed 16-byte entries.

Entries: ``kind u8 | 3 zero bytes | value u64 | crc u32`` (CRC-32 of the first 12 bytes).

- ``ACK`` value = the ack mark: every seq <= it is acknowledged (or gone).
- ``RESERVE`` value = an exclusive bound on the seqs this spool may have handed out; written
  and fsynced before any seq reaches it, so a restart after power loss never re-uses a seq
  that might already be in Kafka.
- ``CLEAN`` value = the next seq, written last by a clean ``close()``.

Reading stops at the first entry that fails its checksum (a torn tail): never a half-written
ledger. At open the ledger is rewritten (temp file, fsync, rename, fsync of the directory) with
just the current state, and again whenever it grows past ``COMPACT_BYTES``.
"""

from __future__ import annotations

import contextlib
import errno
import logging
import os
import struct
import zlib
from dataclasses import dataclass
from pathlib import Path

log = logging.getLogger(__name__)

_BODY = struct.Struct("<B3xQ")
ENTRY_SIZE = _BODY.size + 4
ACK, RESERVE, CLEAN = 1, 2, 3
COMPACT_BYTES = 64 * 1024
SPACE_ERRORS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG})


def encode_entry(kind: int, value: int) -> bytes:
    body = _BODY.pack(kind, value)
    return body + zlib.crc32(body).to_bytes(4, "little")


@dataclass(slots=True)
class LedgerState:
    ack_mark: int = 0
    reserved: int = 1
    clean_next_seq: int | None = None
    """Set when the last entry was a clean close: the spool stopped in order."""
    damaged_at: int | None = None
    """Offset of the first entry that failed its checksum, if any."""
    fresh: bool = False
    """There was no ledger: a new spool."""


def parse_ledger(data: bytes) -> LedgerState:
    state = LedgerState(fresh=not data)
    for off in range(0, len(data), ENTRY_SIZE):
        entry = data[off : off + ENTRY_SIZE]
        body = entry[: _BODY.size]
        if len(entry) < ENTRY_SIZE or zlib.crc32(body) != int.from_bytes(entry[_BODY.size :], "little"):
            state.damaged_at = off
            break
        kind, value = _BODY.unpack(body)
        state.clean_next_seq = value if kind == CLEAN else None
        if kind == ACK:
            state.ack_mark = max(state.ack_mark, value)
        elif kind == RESERVE:
            state.reserved = max(state.reserved, value)
        elif kind != CLEAN:
            state.damaged_at = off
            break
    return state


def fsync_dir(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


class Ledger:
    """The ledger file of one spool directory. Not thread-safe: the spool holds its lock."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._fd = -1
        self._size = 0
        self._ack_mark = 0
        self._reserved = 1
        self._needs_rewrite = False
        self._dirty = False
        self.failures = 0

    def open(self) -> LedgerState:
        tmp = self.path.with_suffix(".tmp")
        tmp.unlink(missing_ok=True)
        try:
            data = self.path.read_bytes()
        except FileNotFoundError:
            data = b""
        state = parse_ledger(data)
        if state.damaged_at is not None:
            log.warning(
                "spool ledger %s: entry at offset %d fails its checksum; %d trailing bytes ignored",
                self.path,
                state.damaged_at,
                len(data) - state.damaged_at,
            )
        self._ack_mark, self._reserved = state.ack_mark, state.reserved
        self._rewrite(strict=True)
        return state

    def _rewrite(self, *, strict: bool) -> bool:
        """Replace the file by the current state, atomically. ``strict`` raises on failure."""
        tmp = self.path.with_suffix(".tmp")
        data = encode_entry(ACK, self._ack_mark) + encode_entry(RESERVE, self._reserved)
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            try:
                if os.write(fd, data) != len(data):
                    raise OSError(errno.ENOSPC, "short write")
                os.fsync(fd)
            finally:
                os.close(fd)
            os.replace(tmp, self.path)
            fsync_dir(self.path.parent)
        except OSError:
            with contextlib.suppress(OSError):
                tmp.unlink()
            if strict:
                raise
            self.failures += 1
            log.warning("spool ledger %s: rewrite failed; keeping the old file", self.path, exc_info=True)
            return False
        if self._fd >= 0:
            os.close(self._fd)
        self._fd = os.open(self.path, os.O_WRONLY | os.O_APPEND)
        self._size = len(data)
        self._needs_rewrite = False
        self._dirty = False
        return True

    def _append(self, kind: int, value: int, *, sync: bool) -> bool:
        if self._needs_rewrite or self._size >= COMPACT_BYTES:
            return self._rewrite(strict=False) and (not sync or self.sync())
        entry = encode_entry(kind, value)
        try:
            written = os.write(self._fd, entry)
        except OSError as exc:
            if exc.errno not in SPACE_ERRORS:
                raise
            written = -1
        if written != len(entry):
            self.failures += 1
            try:
                os.ftruncate(self._fd, self._size)
            except OSError:
                self._needs_rewrite = True  # a partial entry may remain: replace the file next time
            if self.failures == 1 or self.failures % 1000 == 0:  # a full disk must not flood the log
                log.warning(
                    "spool ledger %s: could not append an entry (disk full?); %d failures so far",
                    self.path,
                    self.failures,
                )
            return False
        self._size += len(entry)
        self._dirty = True
        return not sync or self.sync()

    def record_ack(self, mark: int, *, sync: bool) -> bool:
        self._ack_mark = max(self._ack_mark, mark)
        return self._append(ACK, self._ack_mark, sync=sync)

    def record_reserve(self, bound: int) -> bool:
        """Always synced: the bound must be durable before seqs below it are used."""
        self._reserved = max(self._reserved, bound)
        return self._append(RESERVE, self._reserved, sync=True)

    def record_clean(self, next_seq: int) -> bool:
        return self._append(CLEAN, next_seq, sync=True)

    def sync(self) -> bool:
        """fsync the ledger if anything was appended since the last sync."""
        if not self._dirty or self._fd < 0:
            return self._fd >= 0
        try:
            os.fsync(self._fd)
        except OSError:
            self.failures += 1
            log.warning("spool ledger %s: fsync failed", self.path, exc_info=True)
            return False
        self._dirty = False
        return True

    def close(self) -> None:
        if self._fd >= 0:
            os.close(self._fd)
            self._fd = -1
