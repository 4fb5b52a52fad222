"""What the sender sees of a record buffer: records, batches, counters, options, the protocol.

Two buffers implement ``RecordBuffer``: the durable ``Spool`` (``at_least_once`` mappings) and
the bounded ``MemoryBuffer`` (``best_effort``). Each is one *stream*: one ordered log with its
own sequence numbers, so ``(edge_id, stream, seq)`` names a record uniquely.

Records come and go in *groups* (``fleetlink.wire.groups``): consecutive records appended
together, kept, read back and sent as one unit, so the cost is per group, not per record.

The sender's loop, identical for both::

    batch = buffer.read_unacked(max_records=500, max_bytes=1 << 20)   # whole groups, in flight
    ... send it; on an ok ack:  buffer.ack(batch.first_seq)
    ... on an error ack or a timeout:  buffer.release(batch.first_seq)  # re-read first, same range
    ... on reconnect: buffer.release_all()
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, NamedTuple, Protocol, get_args

from fleetlink.edge.errors import SpoolError
from fleetlink.wire.groups import group_payloads

FullPolicy = Literal["block", "drop_oldest", "drop_newest"]
FsyncPolicy = Literal["always", "batch", "interval"]
FULL_POLICIES: tuple[str, ...] = get_args(FullPolicy)
FSYNC_POLICIES: tuple[str, ...] = get_args(FsyncPolicy)


class SpoolRecord(NamedTuple):
    """One record handed to the sender (a named tuple: thousands are made per second)."""

    seq: int
    timestamp_ms: int
    """When the record was appended (wall clock, ms): what ``oldest_age`` is measured from."""
    payload: bytes


class SpoolGroup(NamedTuple):
    """Records appended together: seqs ``first_seq .. first_seq + records - 1``, as one group."""

    first_seq: int
    records: int
    """How many records the group holds."""
    timestamp_ms: int
    """When the group was appended (wall clock, ms)."""
    group: bytes
    """The group payload (``fleetlink.wire.groups``)."""

    @property
    def last_seq(self) -> int:
        """The seq of the group's last record."""
        return self.first_seq + self.records - 1


@dataclass(frozen=True, slots=True)
class SpoolBatch:
    """Whole groups of unacked records handed to the sender; acked or released as a whole by
    ``first_seq``. Seqs increase but may have gaps (records lost to corruption, seq jumps)."""

    stream: str
    first_seq: int
    last_seq: int
    groups: tuple[SpoolGroup, ...]
    acked: int = 0
    """The buffer's ack mark when it handed the batch out: every record at or below this seq was
    acknowledged or dropped (it travels in the batch's head: ``fleetlink.wire.Batch.acked``)."""

    @property
    def count(self) -> int:
        """Records in the batch."""
        return sum(g.records for g in self.groups)

    @property
    def nbytes(self) -> int:
        """Bytes of the batch's encoded groups."""
        return sum(len(g.group) for g in self.groups)

    @property
    def records(self) -> tuple[SpoolRecord, ...]:
        """Every record of the batch (unpacked: for inspection and tests, not the send path)."""
        out: list[SpoolRecord] = []
        for g in self.groups:
            out.extend(
                SpoolRecord(seq, g.timestamp_ms, payload)
                for seq, payload in enumerate(group_payloads(g.group), g.first_seq)
            )
        return tuple(out)


@dataclass(frozen=True, slots=True)
class SpoolStats:
    """Counters since open (``appended`` ... ``stale_acks``) and the current state."""

    stream: str
    appended: int
    acked: int
    dropped_oldest: int
    dropped_newest: int
    corrupt_skipped: int
    block_timeouts: int
    disk_full: int
    stale_acks: int
    fsyncs: int
    bytes: int
    depth: int
    """Unacked records held (including those in flight)."""
    in_flight: int
    oldest_append_ms: int | None
    """Append time of the oldest unacked record, ``None`` when empty."""
    segments: int
    next_seq: int
    blocked_appenders: int = 0
    """Appenders waiting for room right now (``block`` policy)."""
    lost_missing: int = 0
    """Records lost because their segment file is gone (found at open, counted exactly from the
    ledger's segment table)."""
    damage_unacknowledged: int = 0
    """Damage findings (``edge.spool.damage``) awaiting an operator's acknowledgement, across
    restarts: the edge reports ``degraded`` while there are any."""

    def oldest_age_ms(self, now_ms: int) -> int:
        """Milliseconds the oldest record held has waited at ``now_ms`` (0 when nothing is held)."""
        return 0 if self.oldest_append_ms is None else max(0, now_ms - self.oldest_append_ms)


@dataclass(frozen=True, slots=True)
class SpoolOptions:
    """How a spool is bounded and made durable. See docs/spool.md for the guarantees."""

    max_bytes: int = 1 << 30
    segment_bytes: int = 16 << 20
    policy: FullPolicy = "block"
    block_timeout_s: float = 1.0
    fsync: FsyncPolicy = "interval"
    fsync_interval_ms: int = 100
    fsync_batch: int = 1000
    """``batch`` policy: fsync after this many records (and at least every interval)."""
    group_records: int = 2000
    """A group (one frame, one unit of a WAN batch) holds at most this many records: the edge
    sets its ``wan.batch_max_records``, so that whole groups fill a batch without passing it."""
    group_bytes: int = 1 << 20
    """... and at most this many bytes of record payloads (``wan.batch_max_bytes``)."""

    def __post_init__(self) -> None:
        if self.policy not in FULL_POLICIES:
            raise SpoolError(f"spool policy {self.policy!r} must be one of {', '.join(FULL_POLICIES)}")
        if self.fsync not in FSYNC_POLICIES:
            raise SpoolError(f"fsync {self.fsync!r} must be one of {', '.join(FSYNC_POLICIES)}")
        if self.segment_bytes < 4096:
            raise SpoolError(f"segment_bytes must be at least 4096, got {self.segment_bytes}")
        if self.max_bytes < 2 * self.segment_bytes:
            raise SpoolError(
                f"max_bytes ({self.max_bytes}) must be at least twice segment_bytes "
                f"({self.segment_bytes}) so that acked segments can free room"
            )
        if self.group_records < 1 or self.group_bytes < 1:
            raise SpoolError("group_records and group_bytes must be positive")
        if self.fsync_interval_ms <= 0 or self.fsync_batch <= 0 or self.block_timeout_s < 0:
            raise SpoolError("fsync_interval_ms and fsync_batch must be positive, block_timeout_s >= 0")


class RecordBuffer(Protocol):
    """The interface the WAN sender uses (``Spool`` and ``MemoryBuffer``). Thread-safe."""

    @property
    def stream(self) -> str:
        """The stream's name: one ordered log with its own seqs."""
        ...

    def append(self, payload: bytes) -> int | None:
        """Take one record; returns its seq, or ``None`` when the ``drop_newest`` policy rejected
        it (counted). Under ``block`` raises ``SpoolFullError`` after the timeout."""
        ...

    def append_many(self, payloads: Sequence[bytes]) -> list[int | None]:
        """``append`` for several records at once (one write, one fsync)."""
        ...

    def append_group(self, group: bytes) -> int:
        """Take a group of records made elsewhere (the native data plane); returns how many
        records were taken (the rest dropped by ``drop_newest``, counted). Under ``block`` raises
        ``SpoolFullError`` (``taken`` set) after the timeout. A group above the buffer's group
        limits is split."""
        ...

    def append_groups(self, groups: Sequence[bytes]) -> int:
        """``append_group`` for several groups at once, in order (one write, one fsync)."""
        ...

    def unsent(self) -> int:
        """Records held and not in flight: what the sender may still send (cheap: no stats)."""
        ...

    def read_unacked(
        self, max_records: int, max_bytes: int, *, skip_in_flight: bool = True
    ) -> SpoolBatch | None:
        """The next batch to send (released batches first, then unread records), marked in
        flight; ``None`` when there is nothing to send. ``skip_in_flight=False`` first releases
        everything in flight, so sending restarts from the first unacked record."""
        ...

    def ack(self, first_seq: int) -> bool:
        """The batch starting at ``first_seq`` reached Kafka; False if unknown (stale)."""
        ...

    def release(self, first_seq: int) -> bool:
        """The batch starting at ``first_seq`` must be sent again."""
        ...

    def release_all(self) -> int:
        """Everything in flight must be sent again (e.g. after a reconnect); returns batches."""
        ...

    def note_marks(self, marks: bytes) -> None:
        """A marks block (``edge.spool.marks``): the last ``(publisher GID, seq)`` of samples whose
        records are appended next (or that made none for this buffer); the durable spool writes it
        with the last group of its next append call, the memory buffer keeps nothing."""
        ...

    def stats(self) -> SpoolStats:
        """Counters since open and the buffer's current state."""
        ...

    def close(self) -> None:
        """Close the buffer; later calls raise ``SpoolClosedError``."""
        ...


def check_payloads(payloads: Sequence[bytes], limit: int) -> None:
    """Raise ``SpoolError`` when any payload is longer than ``limit`` bytes."""
    for payload in payloads:
        if len(payload) > limit:
            raise SpoolError(f"record of {len(payload)} bytes exceeds the {limit}-byte record limit")
