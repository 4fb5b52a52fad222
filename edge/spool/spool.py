"""The durable spool: an append-only, checksummed, bounded log on local disk.

A record is taken once ``append`` returns its seq: it has been written to the OS (it survives
``kill -9``) and is fsynced per ``SpoolOptions.fsync``. It leaves when the sender acks the
batch that carried it. See docs/spool.md for the format, guarantees, policies and figures.

Thread-safety: one lock guards the state (appenders are serialised by a second lock); one
writer thread and one sender thread are the intended users. A background thread fsyncs for
the ``interval`` and ``batch`` policies without holding the lock while the disk works.
"""

from __future__ import annotations

import fcntl
import logging
import os
import threading
import time
import zlib
from collections.abc import Callable, Sequence
from pathlib import Path

from fleetlink.edge.errors import SpoolClosedError, SpoolError, SpoolFullError, SpoolLockedError
from fleetlink.edge.spool.api import SpoolBatch, SpoolGroup, SpoolOptions, SpoolStats, check_payloads
from fleetlink.edge.spool.damage import DamageReport, Finding
from fleetlink.edge.spool.frames import (
    FLAG_GROUP,
    FLAG_MARKS,
    HEADER_SIZE,
    SEGMENT_HEADER_SIZE,
    Damage,
    Frame,
    encode_frame,
    peek_timestamp,
)
from fleetlink.edge.spool.grouping import pack_groups
from fleetlink.edge.spool.ledger import Ledger
from fleetlink.edge.spool.marks import (
    SNAPSHOT_NAME,
    Mark,
    MarkBook,
    MarksError,
    decode_marks,
    merge_marks,
    read_snapshot,
    write_snapshot,
)
from fleetlink.edge.spool.reading import read_frames
from fleetlink.edge.spool.recent import RecentFrames
from fleetlink.edge.spool.segments import Cursor, Segment, recover
from fleetlink.edge.spool.tracking import SendTracker, Slice
from fleetlink.edge.spool.writer import DiskFull, SegmentWriter
from fleetlink.wire.groups import group_count, split_group

log = logging.getLogger(__name__)

RECENT_BYTES = 32 << 20
"""Frames appended last kept in memory for the sender (``RecentFrames``): with less, a burst of
60,000 IMU records (41 MB) sent the sender back to the file for part of it."""
RESERVE_BLOCK = 1 << 20
"""Seqs reserved (one fsynced ledger entry) at a time; an unclean restart skips to the bound."""
MAX_SEALING = 8
"""Sealed segments that may wait for the fsync thread at once (each holds a descriptor)."""
COUNTERS = (
    "appended",
    "acked",
    "dropped_oldest",
    "dropped_newest",
    "corrupt_skipped",
    "lost_missing",
    "block_timeouts",
    "disk_full",
    "stale_acks",
    "fsyncs",
)

Item = tuple[int, int, int, bytes]  # first seq, records, append time ms, frame


def wall_ms() -> int:
    """The wall clock in milliseconds since the epoch."""
    return time.time_ns() // 1_000_000


class Spool:
    """The durable spool of one stream in one directory (a ``RecordBuffer``). Use it as a
    context manager, or ``open()`` / ``close()``; the constructor touches nothing on disk."""

    def __init__(
        self,
        directory: Path | str,
        options: SpoolOptions | None = None,
        *,
        stream: str = "durable",
        clock: Callable[[], int] = wall_ms,
    ) -> None:
        self.directory = Path(directory)
        self.options = options or SpoolOptions()
        self._stream = stream
        self._clock = clock
        self._lock = threading.Lock()
        self._appending = threading.Lock()
        self._space = threading.Condition(self._lock)
        self._state = "new"
        self._max_len = self.options.segment_bytes - SEGMENT_HEADER_SIZE - HEADER_SIZE
        # a group must fit one frame of a segment, with its per-record lengths and a marks block
        self._group_bytes = max(1, min(self.options.group_bytes, self._max_len * 3 // 4))
        self._ledger = Ledger(self.directory)
        self._report = DamageReport(self.directory)
        self._marks = MarkBook()
        self._pending_marks = b""
        """The marks block of what was processed since the last write (``note_marks``)."""
        self._writer = SegmentWriter(self.directory)
        self._lock_fd = -1
        self._segments: list[Segment] = []
        self._tracker = SendTracker(Cursor())
        self._recent = RecentFrames(min(RECENT_BYTES, self.options.max_bytes))
        self._next_seq = 1
        self._reserved = 1
        self._persisted_mark = 0
        self._bytes = 0
        self._depth = 0
        self._blocked = 0
        self._refusing = False
        """``block`` gave up once and nothing left since: refuse at once, do not wait again."""
        self._evicting_helps = True
        self._warned: set[str] = set()
        self._c = dict.fromkeys(COUNTERS, 0)
        self._stop = threading.Event()
        self._flusher: threading.Thread | None = None
        self._sealing: list[int] = []
        """Descriptors of segments sealed with records not yet on disk, for the fsync thread."""

    @property
    def stream(self) -> str:
        """The stream's name."""
        return self._stream

    @property
    def origin(self) -> int:
        """The spool's origin: a random id kept in its ledger for its life (0 until opened)."""
        return self._ledger.origin

    # -- lifecycle -------------------------------------------------------------------------------
    def open(self) -> Spool:
        """Lock the directory, recover what is there, start the fsync thread."""
        if self._state != "new":
            raise SpoolError("a Spool object can be opened once", path=self.directory)
        self.directory.mkdir(parents=True, exist_ok=True)
        self._lock_fd = os.open(self.directory / "LOCK", os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(self._lock_fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(self._lock_fd)
            raise SpoolLockedError("the spool is open elsewhere", path=self.directory) from None
        state = self._ledger.read()
        found = recover(self.directory, state, self._max_len)
        self._ledger.open(state, {s.first_seq: s.last_seq for s in found.segments})
        self._segments, self._tracker = found.segments, SendTracker(found.cursor)
        self._depth = found.depth
        self._report.load()
        self._note_findings(found.findings)
        self._restore_marks(found.marks)
        self._delete_spent(found.spent)
        self._bytes = sum(s.size for s in self._segments)
        self._persisted_mark = state.ack_mark
        resume = max(found.last_seq, state.ack_mark) + 1
        if state.clean_next_seq is not None:
            self._next_seq = max(resume, state.clean_next_seq)
        else:  # unclean stop: seqs up to the reservation may have left before a power loss
            self._next_seq = max(resume, state.reserved)
        self._reserved = max(state.reserved, self._next_seq)
        log.info(
            "spool %s opened: %d records unacked in %d segments, next seq %d%s",
            self.directory,
            self._depth,
            len(self._segments),
            self._next_seq,
            " (after an unclean stop)" if state.clean_next_seq is None and not state.fresh else "",
        )
        self._state = "open"
        self._flusher = threading.Thread(target=self._flush_loop, name="spool-fsync", daemon=True)
        self._flusher.start()
        return self

    def _note_findings(self, findings: Sequence[Finding]) -> None:
        """Log, count and report what recovery found; damage reported at an earlier open (still
        on disk) is neither logged at ERROR nor counted again."""
        new = self._report.add(findings, self._clock())
        fresh = {f.key for f in new}
        for finding in findings:
            if finding.key not in fresh:
                log.info(
                    "spool: known damage in %s at offset %d (%s)",
                    finding.file,
                    finding.offset,
                    finding.reason,
                )
                continue
            if finding.reason == "segment_missing":
                self._c["lost_missing"] += finding.records
            else:
                self._c["corrupt_skipped"] += finding.records
            log_finding(self.directory, finding)
        waiting = len(self._report.unacknowledged())
        if waiting:
            log.error(
                "spool %s: %d damage finding(s) await an operator's acknowledgement (fleetlink spool check)",
                self.directory,
                waiting,
            )

    def _restore_marks(self, blocks: Sequence[bytes]) -> None:
        snapshot = read_snapshot(self.directory / SNAPSHOT_NAME)
        if snapshot is None:
            log.warning(
                "spool %s: the marks snapshot is damaged; publishers marked only in deleted segments "
                "will not have what they lost while the edge was down counted",
                self.directory,
            )
        self._marks.update(snapshot or ())
        for block in blocks:
            try:
                self._marks.update(decode_marks(block))
            except MarksError:  # (the frame's checksum held: only a bug writes such a block)
                log.warning("spool %s: a marks block does not decode; ignored", self.directory)
        self._marks.changed = False

    def _delete_spent(self, paths: Sequence[Path]) -> None:
        """Delete the segments recovery found spent, once the snapshot holds their marks; if the
        snapshot cannot be written they stay, to be read again at the next open."""
        if not paths:
            return
        self._marks.changed = True
        self._save_marks()
        if self._marks.changed:
            return
        for path in paths:
            path.unlink(missing_ok=True)

    def close(self) -> None:
        """fsync, record a clean stop, release the directory. Idempotent."""
        with self._lock:
            if self._state != "open":
                self._state = "closed"
                return
            self._state = "closing"
            self._space.notify_all()
        self._stop.set()
        if self._flusher is not None:
            self._flusher.join()
        with self._appending, self._lock:
            self._sync_sealed()
            self._seal()
            self._marks.add_block(self._pending_marks)  # processed, and nothing more comes
            self._pending_marks = b""
            self._save_marks()
            self._ledger.record_ack(self._tracker.mark(), sync=False)
            self._ledger.record_clean(self._next_seq)
            self._ledger.close()
            os.close(self._lock_fd)
            self._state = "closed"

    def __enter__(self) -> Spool:
        return self.open()

    def __exit__(self, *exc: object) -> None:
        self.close()

    def _check_open(self) -> None:
        if self._state != "open":
            raise SpoolClosedError(f"the spool is {self._state}", path=self.directory)

    # -- appending -------------------------------------------------------------------------------
    def append(self, payload: bytes) -> int | None:
        """Take one record: its seq, or ``None`` if ``drop_newest`` rejected it (counted)."""
        return self.append_many((payload,))[0]

    def append_many(self, payloads: Sequence[bytes]) -> list[int | None]:
        """Take records in order (as groups: one write, one fsync when due). Under ``block`` a
        timeout raises ``SpoolFullError`` whose ``taken`` counts the leading records taken."""
        check_payloads(payloads, self._max_len)
        groups = pack_groups(payloads, self.options.group_records, self._group_bytes)
        results: list[int | None] = []
        try:
            self._append_groups(groups, results)
        except SpoolFullError as exc:
            exc.taken = sum(1 for r in results if r is not None)
            raise
        return results

    def append_group(self, group: bytes) -> int:
        """Take a group made elsewhere (split when above the group limits); returns the records
        taken. Under ``block`` a timeout raises ``SpoolFullError`` with ``taken`` set."""
        return self.append_groups((group,))

    def append_groups(self, made: Sequence[bytes]) -> int:
        """``append_group`` for several groups, in order: one write (and one fsync when due)."""
        limit, size = self.options.group_records, self._group_bytes
        groups = [(g, group_count(g)) for group in made for g in split_group(group, limit, size)]
        for g, _count in groups:
            if len(g) > self._max_len:
                raise SpoolError(f"record of {len(g)} bytes exceeds the {self._max_len}-byte record limit")
        results: list[int | None] = []
        try:
            self._append_groups(groups, results)
        except SpoolFullError as exc:
            exc.taken = sum(1 for r in results if r is not None)
            raise
        return sum(1 for r in results if r is not None)

    def _append_groups(self, groups: Sequence[tuple[bytes, int]], results: list[int | None]) -> None:
        """Frame and write ``(group, count)`` in order; ``results`` gets each record's seq or None."""
        crcs = [zlib.crc32(g) for g, _count in groups]
        with self._appending, self._lock:
            self._check_open()
            chunk: list[Item] = []
            size_in_chunk = 0
            marks = self._marks_for(groups[-1][0]) if groups else b""
            self._roll_for(sum(HEADER_SIZE + len(g) for g, _count in groups) + len(marks))
            try:
                for n, ((group, count), crc) in enumerate(zip(groups, crcs, strict=True)):
                    extra = marks if n == len(groups) - 1 else b""
                    size = HEADER_SIZE + len(group) + len(extra)
                    if not self._fits(size_in_chunk + size):
                        self._write_chunk(chunk, results)
                        chunk, size_in_chunk = [], 0
                        if not self._prepare(size, count):
                            results.extend([None] * count)
                            continue
                    first = self._take_seqs(count)
                    ts = self._clock()
                    if extra:  # the marks go with the last group: written with it or not at all
                        frame = encode_frame(
                            first, ts, group + extra, zlib.crc32(extra, crc), flags=FLAG_GROUP | FLAG_MARKS
                        )
                    else:
                        frame = encode_frame(first, ts, group, crc, flags=FLAG_GROUP)
                    chunk.append((first, count, ts, frame))
                    size_in_chunk += size
                    results.extend(range(first, first + count))
                self._write_chunk(chunk, results)
                if marks and results and results[-1] is not None:
                    self._marks.add_block(self._pending_marks)
                    self._pending_marks = b""
            finally:
                if self.options.fsync == "always" or (
                    self.options.fsync == "batch" and self._writer.unsynced >= self.options.fsync_batch
                ):
                    self._sync_locked()

    def _marks_for(self, last_group: bytes) -> bytes:
        """The marks block the frame of ``last_group`` carries (the pending marks), if it fits."""
        marks = self._pending_marks
        return marks if len(last_group) + len(marks) <= self._max_len else b""

    def note_marks(self, marks: bytes) -> None:
        """A marks block: the last ``(publisher GID, seq)`` of samples whose records are appended
        next (or that made none for this spool), written with the last group of the next append
        call."""
        with self._lock:
            pending = self._pending_marks
            self._pending_marks = merge_marks(pending, marks) if pending else marks

    def marks(self) -> list[Mark]:
        """The last ``(publisher GID, seq)`` of every publisher whose samples reached the spool
        (what a previous run left, and what was appended since)."""
        with self._lock:
            return self._marks.items()

    def _roll_for(self, size: int) -> None:
        """Seal the active segment when an append of ``size`` bytes would cross its end: the
        append is then one write, into a new segment (one larger than ``segment_bytes`` when the
        append is), and the marks it carries land with every record they describe. Split over
        two writes, a crash between them would leave records spooled that no mark covers, and
        the restart would count them lost."""
        active = self._writer.segment
        if active is not None and active.count and active.size + size > self.options.segment_bytes:
            self._seal()

    def _fits(self, size: int) -> bool:
        """Whether ``size`` more bytes go in this write: within the active segment or as the first
        write of a segment (``_roll_for``), and within ``max_bytes``."""
        active = self._writer.segment
        header = 0 if active is not None else SEGMENT_HEADER_SIZE
        used = active.size if active is not None else SEGMENT_HEADER_SIZE
        within_segment = used + size <= self.options.segment_bytes or used == SEGMENT_HEADER_SIZE
        return within_segment and self._bytes + header + size <= self.options.max_bytes

    def _take_seqs(self, count: int) -> int:
        """The first of ``count`` consecutive new seqs."""
        seq = self._next_seq
        self._next_seq += count
        if self._next_seq > self._reserved:
            self._reserved = self._next_seq + RESERVE_BLOCK
            if not self._ledger.record_reserve(self._reserved):
                self._warn("reserve", "spool %s: cannot persist the seq reservation", self.directory)
        return seq

    def _prepare(self, size: int, count: int) -> bool:
        """Room for one more frame of ``count`` records, per the policy: True = go ahead, False
        = dropped (counted)."""
        deadline = time.monotonic() + self.options.block_timeout_s
        while True:
            active = self._writer.segment
            need = size + (0 if active is not None else SEGMENT_HEADER_SIZE)
            if self._bytes + need > self.options.max_bytes:
                self._reclaim(force_active=True)
                if self._bytes + need > self.options.max_bytes and not self._full(deadline, count=count):
                    return False
                continue
            if active is not None and active.size + size > self.options.segment_bytes:
                self._seal()
                continue
            return True

    def _full(self, deadline: float, *, disk: bool = False, count: int = 1) -> bool:
        """Apply the policy once. True: retry (room may have been made). False: drop the new
        record (counted). ``block`` waits for acks until ``deadline``, then raises."""
        if disk:
            self._c["disk_full"] += 1
            self._warn("disk", "spool %s: disk full; policy %s applies", self.directory, self.options.policy)
        policy = self.options.policy
        # on a full disk, evicting goes on only while it helps (a write succeeded since the last
        # eviction): a disk filled by something else must not wipe the whole spool
        if policy == "drop_oldest" and self._segments and (not disk or self._evicting_helps):
            self._warn("evict", "spool %s: full; evicting the oldest segment (counted)", self.directory)
            self._remove_first()
            self._evicting_helps = not disk
            return True
        if policy == "block":
            remaining = deadline - time.monotonic()
            if remaining > 0 and not self._refusing:
                self._blocked += 1
                try:
                    self._space.wait(remaining)
                finally:
                    self._blocked -= 1
                self._check_open()
                return True
            self._c["block_timeouts"] += 1
            if not self._refusing:
                self._warn(
                    "block",
                    "spool %s: full for %ss; refusing records until room is made",
                    self.directory,
                    self.options.block_timeout_s,
                )
            # until an acknowledgement makes room, refuse at once: waiting again for each group
            # would hold the intake up for block_timeout each time while nothing can change
            self._refusing = True
            raise SpoolFullError("the spool is full", path=self.directory)
        self._c["dropped_newest"] += count
        self._warn("drop_newest", "spool %s: full; dropping new records (counted)", self.directory)
        return False

    def _write_chunk(self, chunk: list[Item], results: list[int | None]) -> None:
        """Write ``chunk``, whose records are the last entries of ``results``; on a full disk
        one frame at a time, the policy applied to each (its records' results set to None when
        dropped, cut off from ``results`` when ``block`` gives up)."""
        if not chunk:
            return
        try:
            self._write(chunk)
            return
        except DiskFull:
            pass
        deadline = time.monotonic() + self.options.block_timeout_s
        at = len(results) - sum(item[1] for item in chunk)  # where the chunk's records start
        for item in chunk:
            count = item[1]
            while True:
                try:
                    self._write([item])
                    break
                except DiskFull:
                    active = self._writer.segment
                    if active is not None and active.count > 0:
                        self._seal()  # a per-file size limit: a fresh segment may take it
                        continue
                    try:
                        retry = self._full(deadline, disk=True, count=count)
                    except SpoolFullError:
                        del results[at:]
                        raise
                    if not retry:
                        results[at : at + count] = [None] * count
                        break
            at += count

    def _write(self, items: list[Item]) -> None:
        segment = self._writer.segment
        if segment is None:
            segment = self._writer.create(items[0][0])
            self._ledger.record_segment(segment.first_seq)
            self._segments.append(segment)
            self._bytes += SEGMENT_HEADER_SIZE
        data = b"".join(item[3] for item in items)
        offset = segment.size
        self._writer.write(data, [(first, count, ts, len(frame)) for first, count, ts, frame in items])
        self._recent.add(segment, offset, items, len(data))
        records = sum(item[1] for item in items)
        self._bytes += len(data)
        self._depth += records
        self._c["appended"] += records
        self._evicting_helps = True

    # -- leaving the spool -----------------------------------------------------------------------
    def _seal(self) -> None:
        """Close the active segment; the ledger learns the last seq it holds.

        Under the ``interval`` policy the segment's unsynced rest goes to disk on the fsync thread
        (``flush``), within the interval as any record does: an fdatasync here, on the appending
        thread and under the lock, waited for the disk (on a busy disk 0.4 s, appends and reads
        held up meanwhile, bench/bench_fleet.py). Its extent is appended to the ledger now, and is
        on disk before a record enters the next segment (``record_segment`` syncs the ledger): a
        crash that loses the rest shows as a segment shorter than the ledger knew, counted."""
        segment = self._writer.segment
        if segment is None:
            return
        if self.options.fsync != "interval" or self._state != "open":
            self._writer.seal()
            self._ledger.record_extent(segment.first_seq, segment.last_seq, sync=True)
            return
        if len(self._sealing) >= MAX_SEALING:  # the fsync thread is far behind: bound the descriptors
            self._sync_sealed()
        fd = self._writer.seal(sync=False)
        if fd is not None:
            self._sealing.append(fd)
        self._ledger.record_extent(segment.first_seq, segment.last_seq)

    def _sync_sealed(self) -> None:
        """fdatasync and close the segments sealed with records not yet on disk (the lock held)."""
        sealing, self._sealing = self._sealing, []
        self._c["fsyncs"] += self._fdatasync_all(sealing)

    def _fdatasync_all(self, fds: Sequence[int]) -> int:
        """fdatasync and close each of ``fds``; how many went to disk (a failure is warned)."""
        done = 0
        for fd in fds:
            try:
                os.fdatasync(fd)
                done += 1
            except OSError:
                self._warn("fsync", "spool %s: fsync failed", self.directory)
            finally:
                os.close(fd)
        return done

    def _save_marks(self) -> None:
        """Write every mark known to the snapshot (before a segment and its marks go)."""
        if not self._marks.changed:
            return
        try:
            write_snapshot(self.directory / SNAPSHOT_NAME, self._marks.items())
        except OSError as exc:
            self._warn("marks", "spool %s: cannot write the marks snapshot: %s", self.directory, exc)
            return
        self._marks.changed = False

    def _remove_first(self) -> None:
        segment = self._segments.pop(0)
        self._recent.forget(segment)
        if segment is self._writer.segment:
            self._seal()
        dropped, orphaned = self._tracker.segment_removed(segment)
        self._c["dropped_oldest"] += dropped
        self._depth -= dropped + orphaned
        self._bytes -= segment.size
        self._save_marks()
        self._ledger.record_gone(segment.first_seq)
        segment.path.unlink(missing_ok=True)
        self._space.notify_all()

    def _reclaim(self, *, force_active: bool) -> None:
        """Delete the segments every record of which is acknowledged."""
        mark = self._tracker.mark()
        while self._segments and self._segments[0].last_seq <= mark:
            if self._segments[0] is self._writer.segment and not force_active:
                break
            self._remove_first()

    def _mark_moved(self) -> None:
        mark = self._tracker.mark()
        if mark > self._persisted_mark and self._ledger.record_ack(mark, sync=self.options.fsync == "always"):
            self._persisted_mark = mark
        self._reclaim(force_active=False)
        self._refusing = False
        self._space.notify_all()

    # -- the sender's side -----------------------------------------------------------------------
    def read_unacked(
        self, max_records: int = 500, max_bytes: int = 1 << 20, *, skip_in_flight: bool = True
    ) -> SpoolBatch | None:
        """The next batch to send (released ones first), marked in flight; None if none."""
        if max_records < 1 or max_bytes < 1:
            raise SpoolError("max_records and max_bytes must be positive")
        with self._lock:
            self._check_open()
            if not skip_in_flight:
                self._release_all_locked()
            while (queued := self._tracker.take_retry()) is not None:
                resent = self._reread(queued)
                if resent is not None:
                    return resent
            cursor = self._tracker.cursor
            while cursor.index < len(self._segments):
                segment = self._segments[cursor.index]
                if cursor.offset >= segment.size:
                    if segment is self._writer.segment:
                        return None
                    cursor.index, cursor.offset, cursor.consumed = cursor.index + 1, SEGMENT_HEADER_SIZE, 0
                    continue
                recent = self._recent.read(
                    segment, cursor.offset, cursor.next_seq, max_records=max_records, max_bytes=max_bytes
                )
                if recent is not None:  # appended lately: from memory, as written
                    groups, end = recent
                    head, tail = groups[0], groups[-1]
                    count = sum(g.records for g in groups)
                    piece = Slice(
                        head.first_seq, tail.last_seq, count, segment, cursor.offset, end, head.timestamp_ms
                    )
                    self._tracker.start(piece, count)
                    return SpoolBatch(
                        stream=self._stream,
                        first_seq=head.first_seq,
                        last_seq=tail.last_seq,
                        groups=tuple(groups),
                        acked=self._tracker.mark(),
                    )
                found = read_frames(
                    segment,
                    cursor.offset,
                    segment.size,
                    after_seq=cursor.next_seq - 1,
                    max_records=max_records,
                    max_bytes=max_bytes,
                    max_len=self._max_len,
                )
                self._count_damage(
                    segment, [(d, lo, hi, hi - lo + 1) for d, lo, hi in found.damaged], found.lost
                )
                if not found.frames:
                    cursor.offset = found.end
                    continue
                first, last = found.frames[0], found.frames[-1]
                count = sum(f.count for f in found.frames)
                piece = Slice(
                    first.seq,
                    last.last_seq,
                    count,
                    segment,
                    cursor.offset,
                    found.end,
                    first.timestamp_ms,
                )
                self._tracker.start(piece, count)
                return self._batch(piece, found.frames)
            return None

    def _reread(self, queued: Slice) -> SpoolBatch | None:
        """A released batch read again to be sent again. Damaged since it was first read, its
        records left go as a batch of their own and the lost ones are counted (None: none left)."""
        found = read_frames(
            queued.segment,
            queued.offset,
            queued.end,
            after_seq=queued.first_seq - 1,
            max_records=queued.count,
            max_bytes=1 << 62,
            max_len=self._max_len,
        )
        frames = found.frames
        count = sum(f.count for f in frames)
        if count == queued.count and frames[0].seq == queued.first_seq:
            return self._batch(queued, frames)
        self._tracker.finish(queued.first_seq)
        # damage after the last frame left runs to the batch's end (a read alone cannot know)
        tail = frames[-1].last_seq if frames else queued.first_seq - 1
        ranges = [(d, lo, queued.last_seq if lo > tail else hi) for d, lo, hi in found.damaged]
        damaged = [(d, lo, hi, hi - lo + 1) for d, lo, hi in ranges]
        lost = queued.count - count
        unnamed = lost - sum(n for *_r, n in damaged)
        if unnamed > 0:  # gone without damage of its own (the file cut short, known damage grown)
            named = {s for _d, lo, hi in ranges for s in range(lo, hi + 1)}
            named.update(s for f in frames for s in range(f.seq, f.last_seq + 1))
            gone = [s for s in range(queued.first_seq, queued.last_seq + 1) if s not in named]
            missing = Damage(queued.offset, queued.end, "records missing when read again")
            lo, hi = (gone[0], gone[-1]) if gone else (queued.first_seq, queued.last_seq)
            damaged.append((missing, lo, hi, unnamed))
        self._count_damage(queued.segment, damaged, lost)
        if not frames:
            self._mark_moved()
            return None
        first = frames[0]
        piece = Slice(
            first.seq,
            frames[-1].last_seq,
            count,
            queued.segment,
            first.offset,
            queued.end,
            first.timestamp_ms,
        )
        self._tracker.resume(piece)
        self._mark_moved()
        return self._batch(piece, frames)

    def _count_damage(self, segment: Segment, damaged: list[tuple[Damage, int, int, int]], lost: int) -> None:
        """Records lost to damage a read met (``(range, first seq, last seq, records)``):
        counted, and the damage reported."""
        self._c["corrupt_skipped"] += lost
        self._depth -= lost
        if damaged:
            self._report.add(
                [
                    Finding("corrupt", segment.path.name, d.offset, d.end, lo, hi, n, d.reason)
                    for d, lo, hi, n in damaged
                ],
                self._clock(),
            )

    def _batch(self, piece: Slice, frames: Sequence[Frame]) -> SpoolBatch:
        groups = tuple(SpoolGroup(f.seq, f.count, f.timestamp_ms, f.group()) for f in frames)
        return SpoolBatch(
            stream=self._stream,
            first_seq=piece.first_seq,
            last_seq=piece.last_seq,
            groups=groups,
            acked=self._tracker.mark(),
        )

    def ack(self, first_seq: int) -> bool:
        """The batch starting at ``first_seq`` is in Kafka; False (counted) if unknown."""
        with self._lock:
            self._check_open()
            piece = self._tracker.finish(first_seq)
            if piece is None:
                self._c["stale_acks"] += 1
                return False
            self._c["acked"] += piece.count
            if not piece.orphan:
                self._depth -= piece.count
            self._mark_moved()
            return True

    def release(self, first_seq: int) -> bool:
        """The batch starting at ``first_seq`` must be sent again (read back first)."""
        with self._lock:
            self._check_open()
            return self._release_locked(first_seq)

    def _release_locked(self, first_seq: int) -> bool:
        piece = self._tracker.release(first_seq)
        if piece is None:
            return False
        if piece.orphan:  # its segment was evicted: these records are now lost, and counted
            self._c["dropped_oldest"] += piece.count
            self._mark_moved()
        return True

    def release_all(self) -> int:
        """Everything in flight must be sent again (e.g. after a reconnect); returns how many batches."""
        with self._lock:
            self._check_open()
            return self._release_all_locked()

    def _release_all_locked(self) -> int:
        firsts = list(self._tracker.in_flight)
        for first in firsts:
            self._release_locked(first)
        return len(firsts)

    # -- durability and statistics ---------------------------------------------------------------
    def _sync_locked(self) -> None:
        self._sync_sealed()
        if self._writer.sync():
            self._c["fsyncs"] += 1
        self._ledger.sync()

    def flush(self) -> None:
        """fsync what was appended so far (and the segments sealed since), without blocking
        appends while the disk works; the ledger then learns how far the active segment is on
        disk."""
        with self._lock:
            if self._state != "open":
                return
            sealing, self._sealing = self._sealing, []
            pending = self._writer.unsynced
            active = self._writer.segment
            covered = active.last_seq if active is not None else -1
            fd = self._writer.dup()
        sealed = self._fdatasync_all(sealing)
        if sealed:
            with self._lock:
                self._c["fsyncs"] += sealed
        if fd is not None:
            try:
                os.fdatasync(fd)
            except OSError:
                with self._lock:
                    self._writer.unsynced += pending
                self._warn("fsync", "spool %s: fsync failed", self.directory)
                return
            finally:
                os.close(fd)
        with self._lock:
            if fd is not None:
                self._c["fsyncs"] += 1
            if self._state == "open":
                if active is not None and active is self._writer.segment:
                    self._ledger.record_extent(active.first_seq, covered)
                self._ledger.sync()

    def _flush_loop(self) -> None:
        interval = self.options.fsync_interval_ms / 1000
        while not self._stop.wait(interval):
            try:
                self.flush()
            except (OSError, SpoolError):
                log.exception("spool %s: background fsync failed", self.directory)

    def unsent(self) -> int:
        """Records held and not in flight (what ``read_unacked`` may still hand out)."""
        with self._lock:
            return max(0, self._depth - self._tracker.in_flight_records())

    def stats(self) -> SpoolStats:
        """Counters since open and the spool's current state, including unacknowledged damage."""
        with self._lock:
            stamps = [t for t in (self._tracker.oldest_ts(), self._cursor_ts()) if t is not None]
            return SpoolStats(
                stream=self._stream,
                **self._c,
                bytes=self._bytes,
                depth=self._depth,
                in_flight=self._tracker.in_flight_records(),
                oldest_append_ms=min(stamps, default=None),
                segments=len(self._segments),
                next_seq=self._next_seq,
                blocked_appenders=self._blocked,
                damage_unacknowledged=len(self._report.unacknowledged()),
            )

    def damage(self) -> tuple[Finding, ...]:
        """Every damage finding the report keeps (acknowledged ones too)."""
        with self._lock:
            return self._report.findings

    def acknowledge_damage(self) -> list[Finding]:
        """An operator looked at the damage: the findings awaiting it are acknowledged (the spool
        stops reporting them); returns them."""
        with self._lock:
            done = self._report.acknowledge(self._clock())
        for finding in done:
            log.warning(
                "spool %s: damage acknowledged: %s in %s (%s, %d record(s))",
                self.directory,
                finding.reason,
                finding.file,
                finding.seqs(),
                finding.records,
            )
        return done

    def _cursor_ts(self) -> int | None:
        cursor = self._tracker.cursor
        for segment in self._segments[cursor.index :]:
            offset = cursor.offset if segment is self._segments[cursor.index] else SEGMENT_HEADER_SIZE
            if offset < segment.size:
                if offset == SEGMENT_HEADER_SIZE:
                    return segment.first_ts
                fd = os.open(segment.path, os.O_RDONLY)
                try:
                    return peek_timestamp(os.pread(fd, HEADER_SIZE, offset))
                finally:
                    os.close(fd)
        return None

    def _warn(self, key: str, message: str, *args: object) -> None:
        """A condition is logged once at WARNING, then at DEBUG: one fault, few log lines."""
        level = logging.DEBUG if key in self._warned else logging.WARNING
        self._warned.add(key)
        log.log(level, message, *args)


def log_finding(directory: Path, finding: Finding) -> None:
    """One log line per finding: what, file, byte range, seqs, records."""
    path = directory / finding.file
    lost = f"{finding.records} record(s) lost ({finding.seqs()})"
    if finding.reason == "torn_tail":
        log.warning(
            "spool: torn tail in %s at offset %d (%s); %d record(s) skipped (a write a crash cut short)",
            path,
            finding.offset,
            finding.detail,
            finding.records,
        )
    elif finding.reason == "segment_missing":
        log.error("spool: segment %s is missing (%s); %s", path, finding.detail, lost)
    elif finding.reason == "ledger_missing":
        log.error("spool: ledger file %s is missing (%s)", path, finding.detail)
    else:
        what = "segment cut short" if finding.reason == "truncated" else "corrupt data"
        log.error("spool: %s in %s at offset %d (%s); %s", what, path, finding.offset, finding.detail, lost)
