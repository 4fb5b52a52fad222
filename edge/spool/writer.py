"""The active segment: create it, append to it, roll back a partial write, fsync, seal it.

A write either lands whole or not at all: a short write or a full disk is rolled back with
``ftruncate`` to the previous end and reported as ``DiskFull`` for the spool's policy to handle.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from fleetlink.edge.errors import SpoolError
from fleetlink.edge.spool.frames import encode_segment_header
from fleetlink.edge.spool.ledger import SPACE_ERRORS, fsync_dir
from fleetlink.edge.spool.segments import Segment, segment_name


class DiskFull(Exception):  # noqa: N818 - internal signal between writer and spool
    """No room on the disk (or under the file-size limit); nothing was written."""


class SegmentWriter:
    """Owns the file descriptor of the active segment. Not thread-safe (the spool's lock)."""

    def __init__(self, directory: Path) -> None:
        self.directory = directory
        self.segment: Segment | None = None
        self.unsynced = 0
        self._fd = -1

    def create(self, first_seq: int) -> Segment:
        """Start a new active segment whose records begin at ``first_seq``."""
        if self.segment is not None:
            raise SpoolError("internal: a segment is already active", path=self.segment.path)
        path = self.directory / segment_name(first_seq)
        try:
            fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_APPEND, 0o644)
        except OSError as exc:
            if exc.errno in SPACE_ERRORS:
                raise DiskFull from None
            raise SpoolError(f"cannot create a segment: {exc.strerror}", path=path) from exc
        header = encode_segment_header(first_seq)
        try:
            written = os.write(fd, header)
        except OSError as exc:
            if exc.errno not in SPACE_ERRORS:
                os.close(fd)
                raise SpoolError(f"cannot write a segment header: {exc.strerror}", path=path) from exc
            written = -1
        if written != len(header):
            os.close(fd)
            path.unlink()
            raise DiskFull
        fsync_dir(self.directory)  # the new name must survive a power loss as well as its data
        self._fd = fd
        self.segment = Segment(path=path, first_seq=first_seq, size=len(header), sealed=False)
        return self.segment

    def write(self, data: bytes, items: Sequence[tuple[int, int, int, int]]) -> None:
        """Append ``data`` holding frames ``items`` = ``(first seq, records, append_ms, frame_len)``."""
        segment = self.segment
        if segment is None:
            raise SpoolError("internal: no active segment", path=self.directory)
        try:
            written = os.write(self._fd, data)
        except OSError as exc:
            if exc.errno not in SPACE_ERRORS:
                raise SpoolError(
                    f"cannot write: {exc.strerror}", path=segment.path, offset=segment.size
                ) from exc
            written = -1
        if written != len(data):
            try:
                os.ftruncate(self._fd, segment.size)
            except OSError as exc:
                raise SpoolError(
                    f"cannot roll back a partial write: {exc.strerror}",
                    path=segment.path,
                    offset=segment.size,
                ) from exc
            raise DiskFull
        for seq, count, ts, length in items:
            if segment.first_ts is None:
                segment.first_ts = ts
            segment.count += count
            segment.last_seq = seq + count - 1
            segment.size += length
            self.unsynced += count

    def sync(self) -> bool:
        """fdatasync the active segment if anything is unsynced; True if it did."""
        if self._fd < 0 or not self.unsynced:
            self.unsynced = 0
            return False
        os.fdatasync(self._fd)
        self.unsynced = 0
        return True

    def dup(self) -> int | None:
        """A duplicate descriptor to fsync without holding the spool's lock (``None``: nothing
        to sync). The caller closes it; on failure it calls ``unsynced_again``."""
        if self._fd < 0 or not self.unsynced:
            return None
        self.unsynced = 0
        return os.dup(self._fd)

    def seal(self, *, sync: bool = True) -> int | None:
        """Close the active segment; the next write needs ``create``. ``sync``: fdatasync it
        first. Else its descriptor comes back while records in it are not on disk yet (the
        caller fdatasyncs and closes it), ``None`` when every one is."""
        if self.segment is None:
            return None
        kept = None
        if sync:
            self.sync()
        elif self.unsynced:
            kept = self._fd
        if kept is None:
            os.close(self._fd)
        self.unsynced = 0
        self._fd = -1
        self.segment.sealed = True
        self.segment = None
        return kept
