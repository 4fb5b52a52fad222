"""Exactly-once batches: their unwritten records and the stream's new mark, in one transaction.

Batches are submitted per stream in the order the edge sent them. A stream's batches that wait
while its transaction runs are written together in the next one (group commit: an edge keeps
several batches in flight, and one transaction's fixed cost — registering partitions with the
coordinator, the commit — is paid once for all of them); each batch is answered after the
commit that holds it. The mark is produced first in each transaction, so its partition joins
with the records' in one request and the commit has nothing left to send.

A stream's producer is made on its first batch here: registering its ``transactional.id`` fences
the previous owner (another uplink, or this one before a restart), whose open transaction Kafka
aborts; then the marks topic is read up to its end, so the stream's mark is the last one any
owner committed. From there this uplink's own commits keep the mark. A producer fenced later
(another uplink took the stream over) fails its commit: the batches are answered ``error``, the
producer dropped, and the next batch of the stream takes it over again.

A batch whose records Kafka refuses one by one (a non-retriable delivery error) cannot commit:
the group is written again at once, in a new transaction, with those records sent to the
dead-letter topic instead, as the at-least-once path does.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from functools import partial
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

Answer = Callable[[Ack], None]

RunJob = Callable[[TxnSink, int, dict[int, str], Answer], None]
"""Produce, through a sink, the batch's records whose seq is above a given one (0: all), and
call the answer once every delivery report is in: the uplink's batch job. The dict holds seqs
to send to the dead-letter topic unproduced."""

MAX_GROUP = 16
"""Batches of one stream written in one transaction at most."""


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
    out_of_order: int = 0
    """Batches answered ``error`` unwritten: records the edge may still send lay between the
    stream's mark and them (an earlier batch failed, or is still on its way elsewhere)."""
    takeovers: int = 0
    fenced: int = 0
    lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def add(self, **counts: int) -> None:
        """Add ``counts`` (field name -> n) under the lock."""
        with self.lock:
            for name, n in counts.items():
                setattr(self, name, getattr(self, name) + n)


def unsettled_gap(mark_seq: int, batch: Batch) -> tuple[int, int] | None:
    """The seqs between the stream's mark and ``batch`` that the edge may still send, if any: then
    writing the batch would move the mark past records not in Kafka, and a later batch holding
    them would be taken for one sent again and skipped. The edge's ack mark (``batch.acked``)
    says which of them are done (acknowledged, or dropped at the edge: evicted, corrupt, seqs a
    restart skipped). Pure."""
    if batch.first_seq <= mark_seq + 1 or batch.acked >= batch.first_seq - 1:
        return None
    return max(mark_seq, batch.acked) + 1, batch.first_seq - 1


@dataclass
class _Stream:
    sink: TxnSink
    mark: Mark
    used: float
    fresh: bool = True
    """Taken over for the group being written: its mark is the last one any owner committed."""


@dataclass
class _Item:
    pending: Pending
    run: RunJob
    answer: Answer
    after: int = 0
    """Its records above this seq are written (set when its group is planned)."""


@dataclass
class _Plan:
    """A group planned: what one transaction writes, and the answers known before it."""

    mark: Mark
    """The stream's mark once the transaction commits."""
    answers: dict[int, Ack] = field(default_factory=dict)
    todo: list[_Item] = field(default_factory=list)
    riders: list[int] = field(default_factory=list)
    """Batches sent again whose records an earlier batch of the group writes: they share its fate."""


@dataclass
class _Queue:
    items: list[_Item] = field(default_factory=list)
    writing: bool = False


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
        self._queues: dict[MarkKey, _Queue] = {}
        self._writers: set[threading.Thread] = set()
        self._active: set[MarkKey] = set()
        """Streams a group is being written to: never closed as idle."""
        self._stopping = False
        self._lock = threading.Lock()
        self._limiter = LogLimiter(log)
        self.stats = ExactlyOnceStats()

    def submit(self, pending: Pending, run: RunJob, answer: Answer) -> None:
        """Write what the batch holds beyond its stream's mark, exactly once, and ``answer`` (from
        another thread) with an ack covering the whole batch. Submit a stream's batches in order."""
        key = MarkKey.of(pending.batch)
        item = _Item(pending, run, answer)
        with self._lock:
            if self._stopping:
                stopping = True
            else:
                stopping = False
                queue = self._queues.setdefault(key, _Queue())
                queue.items.append(item)
                if queue.writing:
                    return
                queue.writing = True
                thread = threading.Thread(
                    target=self._drain, args=(key, queue), name=f"exactly-once-{key.stream}", daemon=True
                )
                self._writers.add(thread)
        if stopping:
            answer(_answer(pending, "error", "uplink stopping"))
            return
        thread.start()

    def write(self, pending: Pending, run: RunJob) -> Ack:
        """``submit`` and wait for the answer."""
        answers: list[Ack] = []
        answered = threading.Event()

        def answer(ack: Ack) -> None:
            answers.append(ack)
            answered.set()

        self.submit(pending, run, answer)
        answered.wait()
        return answers[0]

    def _drain(self, key: MarkKey, queue: _Queue) -> None:
        """Write the stream's waiting batches, a group per transaction, until none waits."""
        try:
            while True:
                with self._lock:
                    group, queue.items = queue.items[:MAX_GROUP], queue.items[MAX_GROUP:]
                    if not group or self._stopping:
                        left, queue.items = queue.items, []
                        queue.writing = False
                        break
                try:
                    answers = self._write_group(key, group)
                except Exception as exc:  # answer the edge whatever failed: it sends the batches again
                    log.exception("exactly-once %s: batches not written", key)
                    answers = [_answer(i.pending, "error", repr(exc)[:200]) for i in group]
                for item, ack in zip(group, answers, strict=True):
                    self._deliver(key, item, ack)
            for item in group + left:
                self._deliver(key, item, _answer(item.pending, "error", "uplink stopping"))
        finally:
            with self._lock:
                self._writers.discard(threading.current_thread())

    @staticmethod
    def _deliver(key: MarkKey, item: _Item, ack: Ack) -> None:
        """Answer one batch; an answer that fails (the edge's query gone) must not stop the
        stream's writer, or the batches behind it would never be answered."""
        try:
            item.answer(ack)
        except Exception:  # logged; the edge sends the batch again
            log.exception("exactly-once %s: answering batch %d.. failed", key, item.pending.batch.first_seq)

    def _write_group(self, key: MarkKey, group: list[_Item]) -> list[Ack]:
        with self._lock:
            self._active.add(key)
        try:
            return self._write_active_group(key, group)
        finally:
            with self._lock:
                self._active.discard(key)
                stream = self._streams.get(key)
                if stream is not None:
                    stream.used = self._clock()

    def _write_active_group(self, key: MarkKey, group: list[_Item]) -> list[Ack]:
        first = group[0]
        try:
            stream = self._stream(key)
            if not stream.fresh and unsettled_gap(self._after(stream.mark, first), first.pending.batch):
                # another uplink may have written the stream since this one's last commit (the
                # edge moved it there and back): take it over again, to read the mark it left
                self._drop(key, stream)
                stream = self._stream(key)
        except ProduceError as exc:
            return [
                _answer(i.pending, "error", f"exactly-once producer for {key.stream} not ready: {exc}")
                for i in group
            ]
        stream.fresh = False
        plan = self._plan(key, stream, group)
        answers, todo = plan.answers, plan.todo
        if todo:
            dead: dict[int, str] = {}
            while True:
                acks, refused = self._transaction(key, stream, todo, plan.mark, dead)
                if not refused.keys() - dead.keys():
                    break
                dead.update(refused)  # once more at once, those records to the dead-letter topic
            committed = all(a.status == "ok" for a in acks)
            for n in plan.riders:
                pending = group[n].pending
                answers[n] = (
                    _answer(pending, "ok", "")
                    if committed
                    else _answer(
                        pending, "error", "sent again; the batch holding its records was not written"
                    )
                )
            written = iter(acks)
            for n, item in enumerate(group):
                if n not in answers:
                    ack = next(written)
                    answers[n] = replace(
                        ack, first_seq=item.pending.batch.first_seq, last_seq=item.pending.last_seq
                    )
        return [answers[n] for n in range(len(group))]

    def _plan(self, key: MarkKey, stream: _Stream, group: list[_Item]) -> _Plan:
        """Which batches of ``group`` to write in one transaction, and the answers of the others:
        an error for a batch behind seqs not written yet, ok for one committed before."""
        plan = _Plan(mark=stream.mark)
        for n, item in enumerate(group):
            pending = item.pending
            item.after = self._after(plan.mark, item)
            gap = unsettled_gap(item.after, pending.batch)
            if gap is not None:
                self.stats.add(out_of_order=1)
                self._limiter.log(
                    logging.INFO,
                    f"order-{key.stream}",
                    "exactly-once %s: batch %d.. waits for seqs %d..%d (not written yet)",
                    key,
                    pending.batch.first_seq,
                    *gap,
                )
                plan.answers[n] = _answer(
                    pending, "error", f"out of order: seqs {gap[0]}..{gap[1]} not written yet"
                )
                continue
            skipped = pending.at_or_below(item.after) if item.after else 0
            if skipped:
                self.stats.add(skipped_records=skipped)
            if item.after >= pending.last_seq:
                if self._after(stream.mark, item) >= pending.last_seq:
                    plan.answers[n] = _answer(pending, "ok", "")  # committed before
                else:
                    plan.riders.append(n)  # written by an earlier batch of this group, if at all
                continue
            plan.todo.append(item)
            plan.mark = Mark(pending.batch.origin, pending.last_seq)
        return plan

    def _transaction(
        self, key: MarkKey, stream: _Stream, todo: list[_Item], new_mark: Mark, dead: dict[int, str]
    ) -> tuple[list[Ack], dict[int, str]]:
        """One attempt at a group; returns an ack per batch and, when the transaction could not
        commit after records were dead-lettered (Kafka refused them for good, which aborts a
        transaction), those records (seq -> reason), to send to the dead-letter topic unproduced
        next time."""
        sink = stream.sink
        acks: list[Ack | None] = [None] * len(todo)
        left = len(todo)
        lock, all_in = threading.Lock(), threading.Event()

        def answered(n: int, ack: Ack) -> None:
            nonlocal left
            acks[n] = ack
            with lock:
                left -= 1
                if left == 0:
                    all_in.set()

        try:
            sink.begin()
            # the mark first: its partition joins the transaction with the records' in one
            # request, and the commit has nothing left to send (an aborted group aborts it too)
            sink.produce(self._marks_topic, key.kafka_key(), encode_mark(new_mark), on_delivery=_ignore)
            for n, item in enumerate(todo):
                item.run(sink, item.after, dead, partial(answered, n))
            if not all_in.wait(self._timeout_s):
                why = f"not all delivered within {self._timeout_s:g} s"
                self._abort(key, stream, why)
                return [_answer(i.pending, "error", why) for i in todo], {}
            done = [a for a in acks if a is not None]
            failed = next((a for a in done if a.status != "ok"), None)
            if failed is not None:
                self._abort(key, stream, failed.detail)
                why = f"transaction aborted: {failed.detail}"
                return [
                    a if a.status != "ok" else replace(a, status="error", detail=why[:1000]) for a in done
                ], {}
            sink.commit(self._timeout_s)
        except ProduceError as exc:
            self._abort(key, stream, str(exc), fatal=exc.fatal)
            refused = (
                {}
                if exc.fatal
                else {f.seq: f.reason for a in acks if a is not None for f in a.failures if f.dead_lettered}
            )
            return [_answer(i.pending, "error", f"transaction not committed: {exc}") for i in todo], refused
        except Exception as exc:  # noqa: BLE001 - a batch job failed to start: no transaction stays open
            self._abort(key, stream, repr(exc))
            return [_answer(i.pending, "error", f"transaction aborted: {exc!r}"[:1000]) for i in todo], {}
        stream.mark = new_mark
        stream.used = self._clock()
        self._marks.note(key, new_mark)
        self.stats.add(committed=1)
        return done, {}

    @staticmethod
    def _after(mark: Mark, item: _Item) -> int:
        """The seq above which ``item``'s records are not in Kafka (another spool: all of them)."""
        return mark.seq if mark.origin == item.pending.batch.origin else 0

    def _drop(self, key: MarkKey, stream: _Stream) -> None:
        """Forget the stream's producer; the next batch takes the stream over again."""
        with self._lock:
            if self._streams.get(key) is stream:
                del self._streams[key]
        stream.sink.stop(0)

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
        self._drop(key, stream)

    def _stream(self, key: MarkKey) -> _Stream:
        with self._lock:
            stream = self._streams.get(key)
        if stream is not None:
            return stream
        self._close_idle()
        sink = self._make_sink(key.transactional_id(self._prefix)).start()
        # registering the id fenced the previous owner: its open transaction is aborted
        try:
            caught_up = self._marks.catch_up(self._timeout_s)
        except BaseException:
            sink.stop(0)
            raise
        if not caught_up:
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
            idle = [
                k
                for k, s in self._streams.items()
                if now - s.used > self._idle_close_s and k not in self._active
            ]
            closing = [self._streams.pop(k) for k in idle]
        for stream in closing:
            stream.sink.stop(self._timeout_s)

    def stop(self) -> None:
        """Answer the batches still waiting (``error``: the edge sends them again), let the
        transactions under way end (bounded), then close every stream's producer."""
        with self._lock:
            self._stopping = True
            writers = list(self._writers)
        for thread in writers:
            thread.join(self._timeout_s + 5)
        with self._lock:
            closing = list(self._streams.values())
            self._streams.clear()
        for stream in closing:
            stream.sink.stop(5.0)


def _ignore(_delivery: Delivery) -> None:
    """The mark's own delivery report: a mark Kafka did not take fails the commit."""


def _answer(pending: Pending, status: str, detail: str) -> Ack:
    batch = pending.batch
    return Ack(
        edge_id=batch.edge_id,
        stream=batch.stream,
        first_seq=batch.first_seq,
        last_seq=pending.last_seq,
        status="ok" if status == "ok" else "error",
        failures=(),
        detail=detail[:1000],
    )
