"""One exactly-once batch: its unwritten records and the stream's new mark, in one transaction.

A stream's producer is made on its first batch here: registering its ``transactional.id`` fences
the previous owner (another uplink, or this one before a restart), whose open transaction Kafka
aborts; then the marks topic is read up to its end, so the stream's mark is the last one any
owner committed. From there this uplink's own commits keep the mark. A producer fenced later
(another uplink took the stream over) fails its commit: the batch is answered ``error``, the
producer dropped, and the next batch of the stream takes it over again.

A batch whose records Kafka refuses one by one (a non-retriable delivery error) cannot commit:
it is written again at once, in a new transaction, with those records sent to the dead-letter
topic instead, as the at-least-once path does.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Protocol

from fleetlink.common.ratelimit import LogLimiter
from fleetlink.uplink.errors import ProduceError
from fleetlink.uplink.exactly_once.marks import Mark, MarkKey, encode_mark
from fleetlink.uplink.exactly_once.marks_reader import MarksReader
from fleetlink.uplink.ingest import Sink
from fleetlink.uplink.producer import Delivery
from fleetlink.wire import Ack, Batch

log = logging.getLogger(__name__)


class TxnSink(Sink, Protocol):
    """A transactional producer (``uplink.producer.KafkaSink`` or ``uplink.native_sink.NativeSink``
    made with a transactional id)."""

    def start(self) -> TxnSink:
        """Create the producer and register its transactional id (fencing other holders)."""

    def begin(self) -> None:
        """Open a transaction."""

    def commit(self, timeout_s: float) -> None:
        """Commit the open transaction (``ProduceError``, ``fatal`` when fenced)."""

    def abort(self, timeout_s: float) -> None:
        """Abort the open transaction."""

    def stop(self, flush_timeout: float = 10.0) -> int:
        """Close the producer; returns records not delivered."""


SinkFactory = Callable[[str], TxnSink]
"""Makes the (unstarted) producer of a transactional id."""

RunJob = Callable[[TxnSink, int, dict[int, str]], Ack]
"""Produce, through a sink, the batch's records whose seq is above a given one (0: all), and
wait for every delivery report: the uplink's batch job run to its end. The dict holds seqs to
send to the dead-letter topic unproduced."""


@dataclass(frozen=True, slots=True)
class Pending:
    """An exactly-once batch as the writer sees it."""

    batch: Batch
    """Its head: site, edge, stream, origin, first seq."""
    last_seq: int
    at_or_below: Callable[[int], int]
    """How many of its records have a seq at or below a given one."""


@dataclass
class ExactlyOnceStats:
    """What the exactly-once path did since the uplink started."""

    committed: int = 0
    aborted: int = 0
    skipped_records: int = 0
    """Records of batches sent again that were already in Kafka (at or below their mark)."""
    takeovers: int = 0
    fenced: int = 0
    lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def add(self, **counts: int) -> None:
        """Add ``counts`` (field name -> n) under the lock."""
        with self.lock:
            for name, n in counts.items():
                setattr(self, name, getattr(self, name) + n)


@dataclass
class _Stream:
    sink: TxnSink
    mark: Mark
    used: float


class ExactlyOnceWriter:
    """The transactional producers of the exactly-once streams this uplink serves."""

    def __init__(
        self,
        make_sink: SinkFactory,
        *,
        marks: MarksReader,
        marks_topic: str,
        prefix: str,
        transaction_timeout_s: float,
        idle_close_s: float,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self._make_sink = make_sink
        self._marks = marks
        self._marks_topic = marks_topic
        self._prefix = prefix
        self._timeout_s = transaction_timeout_s
        self._idle_close_s = idle_close_s
        self._clock = clock
        self._streams: dict[MarkKey, _Stream] = {}
        self._lock = threading.Lock()
        self._limiter = LogLimiter(log)
        self.stats = ExactlyOnceStats()

    def write(self, pending: Pending, run: RunJob) -> Ack:
        """Write what the batch holds beyond its stream's mark, exactly once; the ack covers the
        whole batch. Called for one stream at a time (the uplink runs an edge's batches in order)."""
        batch = pending.batch
        key = MarkKey.of(batch)
        try:
            stream = self._stream(key)
        except ProduceError as exc:
            return _answer(
                batch, pending.last_seq, "error", f"exactly-once producer for {key.stream} not ready: {exc}"
            )
        after = stream.mark.seq if stream.mark.origin == batch.origin else 0  # another spool: all of it
        skipped = pending.at_or_below(after) if after else 0
        if skipped:
            self.stats.add(skipped_records=skipped)
        if after >= pending.last_seq:
            return _answer(batch, pending.last_seq, "ok", "")
        dead: dict[int, str] = {}
        while True:
            ack, refused = self._transaction(key, stream, pending, after=after, run=run, dead=dead)
            if not refused.keys() - dead.keys():
                return replace(ack, first_seq=batch.first_seq, last_seq=pending.last_seq)
            dead.update(refused)  # once more at once, those records to the dead-letter topic

    def _transaction(
        self,
        key: MarkKey,
        stream: _Stream,
        pending: Pending,
        *,
        after: int,
        run: RunJob,
        dead: dict[int, str],
    ) -> tuple[Ack, dict[int, str]]:
        """One attempt; returns the ack and, when the transaction could not commit after records
        were dead-lettered (Kafka refused them for good, which aborts a transaction), those
        records (seq -> reason), to send to the dead-letter topic unproduced next time."""
        sink = stream.sink
        ack: Ack | None = None
        try:
            sink.begin()
            ack = run(sink, after, dead)
            if ack.status != "ok":
                self._abort(key, stream, ack.detail)
                return ack, {}
            new_mark = Mark(pending.batch.origin, pending.last_seq)
            sink.produce(self._marks_topic, key.kafka_key(), encode_mark(new_mark), on_delivery=_ignore)
            sink.commit(self._timeout_s)
        except ProduceError as exc:
            self._abort(key, stream, str(exc), fatal=exc.fatal)
            refused = (
                {} if ack is None or exc.fatal else {f.seq: f.reason for f in ack.failures if f.dead_lettered}
            )
            return _answer(
                pending.batch, pending.last_seq, "error", f"transaction not committed: {exc}"
            ), refused
        stream.mark = new_mark
        stream.used = self._clock()
        self._marks.note(key, new_mark)
        self.stats.add(committed=1)
        return ack, {}

    def _abort(self, key: MarkKey, stream: _Stream, why: str, *, fatal: bool = False) -> None:
        self.stats.add(aborted=1)
        if not fatal:
            try:
                stream.sink.abort(self._timeout_s)
                self._limiter.log(
                    logging.WARNING,
                    f"abort-{key.stream}",
                    "exactly-once %s: transaction aborted: %s",
                    key,
                    why,
                )
                return
            except ProduceError as exc:
                why = f"{why}; the abort failed too: {exc}"
        # fenced (another uplink owns the stream now) or broken: the next batch takes it over
        self.stats.add(fenced=1)
        log.warning("exactly-once %s: producer given up (%s); the next batch takes the stream over", key, why)
        with self._lock:
            if self._streams.get(key) is stream:
                del self._streams[key]
        stream.sink.stop(0)

    def _stream(self, key: MarkKey) -> _Stream:
        with self._lock:
            stream = self._streams.get(key)
        if stream is not None:
            return stream
        self._close_idle()
        sink = self._make_sink(key.transactional_id(self._prefix)).start()
        # registering the id fenced the previous owner: its open transaction is aborted
        if not self._marks.catch_up(self._timeout_s):
            sink.stop(0)
            raise ProduceError("the marks topic could not be read to its end", code="_MARKS", retriable=True)
        stream = _Stream(sink, self._marks.mark(key), self._clock())
        log.info(
            "exactly-once %s: taken over at mark %d of origin %016x", key, stream.mark.seq, stream.mark.origin
        )
        self.stats.add(takeovers=1)
        with self._lock:
            self._streams[key] = stream
        return stream

    def _close_idle(self) -> None:
        now = self._clock()
        with self._lock:
            idle = [k for k, s in self._streams.items() if now - s.used > self._idle_close_s]
            closing = [self._streams.pop(k) for k in idle]
        for stream in closing:
            stream.sink.stop(self._timeout_s)

    def stop(self) -> None:
        """Close every stream's producer (no transaction is open between batches)."""
        with self._lock:
            closing = list(self._streams.values())
            self._streams.clear()
        for stream in closing:
            stream.sink.stop(5.0)


def _ignore(_delivery: Delivery) -> None:
    """The mark's own delivery report: a mark Kafka did not take fails the commit."""


def _answer(batch: Batch, last_seq: int, status: str, detail: str) -> Ack:
    return Ack(
        edge_id=batch.edge_id,
        stream=batch.stream,
        first_seq=batch.first_seq,
        last_seq=last_seq,
        status="ok" if status == "ok" else "error",
        failures=(),
        detail=detail[:1000],
    )
