"""The processing thread: samples -> records -> the buffer of each record's delivery class.

One thread, so the records of a robot are appended in the order their samples arrived. It takes
samples from the ``SampleSource`` (the native data plane: records it made already, and samples
for the general path) and control items (registration events) from the ``Intake``, turns
samples into records (``RecordMaker``), ticks the stages a few times a second, and appends each
chunk with one ``append_many`` per buffer. A full spool under the ``block`` policy makes this
thread wait (up to the spool's ``block_timeout``) while the source's intake fills up and then
drops, counted: the Zenoh callbacks never wait. Without a source (unit tests) samples come
through the ``Intake`` too.

Each chunk's publisher marks (the last sequence number of every publisher whose samples it held)
go to the ``at_least_once`` buffer just before its last append of the chunk, so the durable spool
writes them with those records (``edge.spool.marks``): after a crash they say exactly which
samples reached the spool.

A sample that comes before its robot's registration (``early``) waits for it, holding back its
publisher's mark as a claim-checked record does until its upload: made into records when the
robot registers, counted as unmapped when it does not in time.
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, fields
from typing import Protocol

from fleetlink.common.ratelimit import LogLimiter
from fleetlink.edge.claim_check import Claimed, ClaimJob
from fleetlink.edge.errors import SpoolError, SpoolFullError
from fleetlink.edge.mapping import Delivery
from fleetlink.edge.runtime.early import EarlySamples
from fleetlink.edge.runtime.intake import Intake
from fleetlink.edge.runtime.outgoing import Outgoing
from fleetlink.edge.runtime.records import RecordMaker
from fleetlink.edge.spool import RecordBuffer
from fleetlink.edge.spool.marks import decode_marks, encode_marks, merge_marks
from fleetlink.roswire.errors import RoswireError
from fleetlink.roswire.subscriber import RosSample
from fleetlink.wire.groups import group_count

log = logging.getLogger(__name__)


@dataclass(frozen=True, slots=True)
class Rejected:
    """A sample a subscriber refused (``on_error``), with the topic it was subscribed on."""

    topic: str
    error: RoswireError
    received_ns: int


@dataclass(frozen=True, slots=True)
class Emit:
    """Records made outside the processor (registration events), appended in order."""

    records: tuple[Outgoing, ...]


Item = RosSample | Rejected | Emit | Claimed
"""``Claimed``: a claim job the uploader finished (its object stored, or not)."""


class Uploader(Protocol):
    """Where claim jobs go (``fleetlink.edge.runtime.offloader.Offloader``)."""

    def submit(self, job: ClaimJob) -> Claimed | None:
        """Take ``job``; a ``Claimed`` when it is finished at once (nothing to upload and nothing
        ahead of it, or refused), else None: it comes back later through ``Processor.post``."""
        ...


@dataclass(slots=True)
class Taken:
    """What one ``SampleSource.take`` brought: record groups made natively per delivery class
    (``fleetlink.wire.groups``), samples for the general path, the shortest linger of each
    class's records (``None``: the default), samples taken in all."""

    groups: dict[Delivery, list[bytes]] = field(default_factory=dict)
    samples: list[RosSample | Rejected] = field(default_factory=list)
    lingers: dict[Delivery, float | None] = field(default_factory=dict)
    count: int = 0
    oldest_received_ns: int = 0
    """When the oldest sample of this take arrived (0: none): the lag behind the robots."""
    marks: bytes = b""
    """A marks block (``fleetlink.edge.spool.marks``): the last ``(publisher GID, seq)`` of each
    publisher whose samples the groups hold or that came for the general path."""


class SampleSource(Protocol):
    """Where samples come from (``fleetlink.edge.runtime.dataplane.NativeSource``)."""

    def take(self, max_samples: int, timeout_s: float) -> Taken:
        """Take up to ``max_samples``, waiting up to ``timeout_s`` seconds for the first; processing thread
        only."""
        ...

    def wake(self) -> None:
        """Make a waiting ``take`` return now; from any thread."""
        ...

    def sync(self, table_version: int) -> None:
        """Forget the fast plans when the mapping table changed since the last call."""
        ...

    def install(self, maker: RecordMaker, keys: Iterable[str]) -> None:
        """Hand the fast plans ``maker`` made for the data ``keys`` to the source."""
        ...


@dataclass(slots=True)
class ProcessorStats:
    """The processing thread's running totals: samples taken, records made and appended, and losses."""

    samples: int = 0
    records: int = 0
    appended: int = 0
    spool_dropped: int = 0
    """Refused by a full buffer's ``drop_newest`` policy."""
    spool_refused: int = 0
    """Not taken because the ``block`` policy timed out, or the record exceeds the buffer's limit."""
    errors: int = 0
    takes: int = 0
    """Chunks taken from the data plane with a sample in them (``samples / takes``: how many come
    together)."""

    def as_dict(self) -> dict[str, int]:
        """The counters by field name."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


class Processor:
    """The processing thread: takes samples and control items, makes records of them and appends each chunk
    to the buffer of its delivery class."""

    def __init__(
        self,
        intake: Intake[Item],
        maker: RecordMaker,
        buffers: Mapping[Delivery, RecordBuffer],
        *,
        on_appended: Callable[[Delivery, float], object] | None = None,
        source: SampleSource | None = None,
        table_version: Callable[[], int] = lambda: 0,
        default_linger_s: float = 0.0,
        tick_interval_s: float = 0.1,
        chunk: int = 512,
        clock_ns: Callable[[], int] = time.time_ns,
        uploader: Uploader | None = None,
        early: EarlySamples | None = None,
    ) -> None:
        self.intake = intake
        self.early = early
        """Samples waiting for their robot's registration (None: not held, counted as unmapped)."""
        self._early_version: int | None = None
        self.maker = maker
        self.uploader = uploader
        self._held: dict[bytes, deque[int]] = {}
        """Publisher GID -> sequence numbers of its samples whose records wait: for an upload, or
        for their robot's registration (in arrival order: the first usually leaves first)."""
        self._held_jobs: dict[int, tuple[bytes, int]] = {}
        self._released: list[tuple[bytes, int]] = []
        """Where claim-checked payloads go; without one they are dead-lettered."""
        self.buffers = buffers
        self._on_appended = on_appended or _nothing
        self.source = source
        self._table_version = table_version
        self.lag_ns = 0
        """How long the oldest sample of the last take had waited (receipt -> processing)."""
        self.default_linger_s = default_linger_s
        """The linger of records that bring none (the edge passes its ``wan.linger``)."""
        self.tick_interval_s = tick_interval_s
        self.chunk = chunk
        self._clock_ns = clock_ns
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()
        self._limiter = LogLimiter(log)
        self.stats = ProcessorStats()

    def post(self, item: Item) -> None:
        """Queue a control item (it is never dropped) and wake the thread for it."""
        self.intake.offer(item, force=True)
        if self.source is not None:
            self.source.wake()

    def start(self) -> Processor:
        """Start the processing thread (once); returns ``self``."""
        if self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name="edge-processor", daemon=True)
            self._thread.start()
        return self

    def stop(self, timeout_s: float = 10.0) -> None:
        """Process what is queued (the intake should be closed first), then stop."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout_s)
            self._thread = None

    def __enter__(self) -> Processor:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def counters(self) -> dict[str, object]:
        """Thread-safe copies of the maker's and the processor's counters."""
        with self._lock:
            return {
                "processor": self.stats.as_dict(),
                "mappings": {name: c.as_dict() for name, c in self.maker.counters.items()},
                "stages": self.maker.stage_counters(),
                "unknown_type_samples": self.maker.unknown_type_samples,
                "rejected_samples": self.maker.rejected,
                "oversized": self.maker.oversized,
                "claims": dataclasses.asdict(self.maker.claim_stats),
                "early": self._early_counters(),
            }

    def _early_counters(self) -> dict[str, int]:
        early = self.early
        if early is None:
            return {}
        return {**dataclasses.asdict(early.stats), "waiting": len(early), "waiting_bytes": early.bytes}

    # -- the loop --------------------------------------------------------------------------------
    def _run(self) -> None:
        last_tick = 0
        tick_ns = int(self.tick_interval_s * 1e9)
        while True:
            taken = self._take()
            wait_s = 0.0 if self.source is not None else self.tick_interval_s
            items = self.intake.take(self.chunk, timeout=wait_s)
            if not items and not taken.count and self._stop.is_set():
                return
            now = self._clock_ns()
            if taken.count:
                self.stats.takes += 1
            if taken.oldest_received_ns:
                self.lag_ns = max(0, now - taken.oldest_received_ns)
            try:
                with self._lock:
                    version = self._table_version()
                    if self.source is not None:
                        self.source.sync(version)
                    out = self._early_ones(version, now)
                    out.extend(self._records(items, now))
                    if taken.samples:
                        out.extend(self._records(taken.samples, now))
                        if self.source is not None:
                            keys = {s.key for s in taken.samples if isinstance(s, RosSample)}
                            self.source.install(self.maker, keys)
                    self.stats.samples += taken.count - len(taken.samples)
                    if now - last_tick >= tick_ns:
                        last_tick = now
                        out.extend(self.maker.tick(now))
                    if self.maker.claims:
                        out.extend(self._hand_over(self.maker.drain_claims()))
                self._append(out, taken, self._marks(items, taken))
            except Exception as exc:  # noqa: BLE001 - one bad chunk must not stop the edge; logged, counted
                self.stats.errors += 1
                self._limiter.log(
                    logging.ERROR,
                    "chunk",
                    "edge processor: a chunk of %d item(s) failed: %r",
                    len(items) + taken.count,
                    exc,
                )

    def _take(self) -> Taken:
        if self.source is None:
            return Taken()
        return self.source.take(self.chunk, self.tick_interval_s)

    def _records(self, items: Sequence[Item], now_ns: int) -> list[Outgoing]:
        out: list[Outgoing] = []
        extend, make = out.extend, self.maker.make
        for item in items:
            if isinstance(item, RosSample):
                self.stats.samples += 1
                if self.early is not None and self._waits(item, now_ns, out):
                    continue
                extend(make(item, now_ns))
            elif isinstance(item, Rejected):
                out.extend(self.maker.rejected_sample(item.topic, item.error, item.received_ns))
            elif isinstance(item, Claimed):
                self._release(item.job)
                out.extend(self.maker.finish_claim(item))
            else:
                out.extend(item.records)
            if self.maker.claims:  # in order: a claim job's record may come back at once
                source = item if isinstance(item, RosSample) else None
                out.extend(self._hand_over(self.maker.drain_claims(), source))
        return out

    def _waits(self, sample: RosSample, now_ns: int, out: list[Outgoing]) -> bool:
        """Whether ``sample`` waits for its robot's registration (``self.early``: no mapping takes
        it yet, one will once its robot registers). When its robot registered since samples of its
        topic began to wait, those are made into records first (into ``out``), in order."""
        early = self.early
        assert early is not None
        topic = sample.topic
        if early.holds(topic):
            if self.maker.takes(topic):
                self._let_go(early.release(topic), now_ns, out)
                return False
        elif not self.maker.waits_for_robot(sample):
            return False
        if not early.add(sample, now_ns):
            return False  # the hold is full (or given up on this topic): counted as unmapped
        self.maker.keep_general(sample)
        if sample.gid is not None and sample.seq is not None:
            self._held.setdefault(sample.gid, deque()).append(sample.seq)
        return True

    def _early_ones(self, table_version: int, now_ns: int) -> list[Outgoing]:
        """The records of the samples whose robot registered; those that waited too long given up."""
        early = self.early
        out: list[Outgoing] = []
        if early is None:
            return out
        if table_version != self._early_version:
            self._early_version = table_version
            early.retry()  # topics given up on may have a robot now
        if not len(early):
            return out
        for topic in early.topics():
            if self.maker.takes(topic):
                self._let_go(early.release(topic), now_ns, out)
        for sample in early.expired(now_ns):
            self._unhold(sample)
            self.maker.count_unmapped(sample.topic)
        return out

    def _let_go(self, samples: Sequence[RosSample], now_ns: int, out: list[Outgoing]) -> None:
        for sample in samples:
            self._unhold(sample)
            out.extend(self.maker.make(sample, now_ns))
            if self.maker.claims:
                out.extend(self._hand_over(self.maker.drain_claims(), sample))

    def _unhold(self, sample: RosSample) -> None:
        """A sample that waited leaves the hold: its mark may go with this chunk's."""
        if sample.gid is not None and sample.seq is not None:
            self._free_mark(sample.gid, sample.seq)

    def _free_mark(self, gid: bytes, seq: int) -> None:
        """The record of ``seq`` (held back) enters the spool now: its mark goes with the chunk's."""
        seqs = self._held.get(gid)
        if seqs is not None:
            with contextlib.suppress(ValueError):
                seqs.remove(seq)  # at once when it is the first (a deque: no shifting)
            if not seqs:
                del self._held[gid]
        self._released.append((gid, seq))

    def _hand_over(self, jobs: Sequence[ClaimJob], source: RosSample | None = None) -> list[Outgoing]:
        """Give claim jobs to the uploader; the records of those finished at once. A job that
        waits for its upload holds back its publisher's spool mark (``_marks``)."""
        out: list[Outgoing] = []
        for job in jobs:
            done = (
                self.uploader.submit(job)
                if self.uploader is not None
                else Claimed(job, error="the edge has no object store")
            )
            if done is not None:
                out.extend(self.maker.finish_claim(done))
            elif source is not None and source.gid is not None and source.seq is not None:
                self._held_jobs[id(job)] = (source.gid, source.seq)
                self._held.setdefault(source.gid, deque()).append(source.seq)
        return out

    def _release(self, job: ClaimJob) -> None:
        """A held job came back: its record enters the spool now, and with it its mark."""
        held = self._held_jobs.pop(id(job), None)
        if held is not None:
            self._free_mark(*held)

    def _marks(self, items: Sequence[Item], taken: Taken) -> bytes:
        """The chunk's marks block (``_marks_of``), with those of the claim-checked records it
        spools, and none past a sample whose record still waits for its upload: a crash loses
        that record, so the restart must count it (``lost_at_restart``)."""
        block = _marks_of(items, taken)
        if not self._released and not self._held:
            return block
        found = dict(decode_marks(block)) if block else {}
        for gid, seq in self._released:
            known = found.get(gid)
            if known is None or seq > known:
                found[gid] = seq
        self._released = []
        for gid, seqs in self._held.items():
            known = found.get(gid)
            if known is not None and known >= min(seqs):
                if min(seqs) > 0:
                    found[gid] = min(seqs) - 1
                else:
                    del found[gid]
        return encode_marks(found.items()) if found else b""

    def _append(self, out: list[Outgoing], taken: Taken, marks: bytes) -> None:
        payloads: dict[Delivery, list[bytes]] = {}
        lingers: dict[Delivery, float] = {}  # per buffer, the shortest linger of what it got
        default = self.default_linger_s
        for delivery, own in taken.lingers.items():
            lingers[delivery] = default if own is None else own
        for delivery, payload, own in out:
            linger = default if own is None else own
            pending = payloads.get(delivery)
            if pending is None:
                pending = payloads[delivery] = []
            if linger < lingers.get(delivery, linger + 1):
                lingers[delivery] = linger
            pending.append(payload)
        durable = self.buffers.get("at_least_once")
        for delivery in {*taken.groups, *payloads}:
            buffer = self.buffers[delivery]
            groups = taken.groups.get(delivery)
            records = payloads.get(delivery)
            if groups:
                if marks and buffer is durable and records is None:
                    buffer.note_marks(marks)  # written with the last group
                    marks = b""
                self._append_groups(delivery, buffer, groups)
            if records is not None:
                if marks and buffer is durable:
                    buffer.note_marks(marks)
                    marks = b""
                self.stats.records += len(records)
                self._append_to(delivery, buffer, records)
            self._on_appended(delivery, lingers.get(delivery, default))
        if marks and durable is not None:  # nothing durable this time: written with the next append
            durable.note_marks(marks)

    def _append_groups(self, delivery: Delivery, buffer: RecordBuffer, groups: Sequence[bytes]) -> None:
        stats = self.stats
        count = sum(group_count(group) for group in groups)
        stats.records += count
        try:
            taken = buffer.append_groups(groups)
        except SpoolFullError as exc:
            stats.appended += exc.taken
            stats.spool_refused += count - exc.taken
            self._limiter.log(
                logging.WARNING,
                f"full-{delivery}",
                "%s buffer full: %d record(s) refused (%s)",
                delivery,
                count - exc.taken,
                exc,
            )
            return
        except SpoolError as exc:  # a group above the buffer's size limit (none taken): one at a time
            if len(groups) > 1:
                stats.records -= count
                for group in groups:
                    self._append_groups(delivery, buffer, (group,))
                return
            stats.spool_refused += count
            self._limiter.log(
                logging.WARNING, f"refused-{delivery}", "%s buffer refused a group: %s", delivery, exc
            )
            return
        stats.appended += taken
        stats.spool_dropped += count - taken

    def _append_to(self, delivery: Delivery, buffer: RecordBuffer, payloads: list[bytes]) -> None:
        stats = self.stats
        try:
            results = buffer.append_many(payloads)
        except SpoolFullError as exc:
            stats.appended += exc.taken
            stats.spool_refused += len(payloads) - exc.taken
            self._limiter.log(
                logging.WARNING,
                f"full-{delivery}",
                "%s buffer full: %d record(s) refused (%s)",
                delivery,
                len(payloads) - exc.taken,
                exc,
            )
            return
        except SpoolError:  # a record above the buffer's size limit: append one by one
            results = []
            for payload in payloads:
                try:
                    results.extend(buffer.append_many([payload]))
                except SpoolError as exc:
                    stats.spool_refused += 1
                    self._limiter.log(
                        logging.WARNING,
                        f"refused-{delivery}",
                        "%s buffer refused a record of %d bytes: %s",
                        delivery,
                        len(payload),
                        exc,
                    )
        taken = sum(1 for r in results if r is not None)
        stats.appended += taken
        stats.spool_dropped += len(results) - taken


def _marks_of(items: Sequence[Item], taken: Taken) -> bytes:
    """The chunk's marks block: the data plane's (its records and the samples it handed to the
    general path) and those of the samples that came through the intake (without a data plane)."""
    found: dict[bytes, int] = {}
    for sample in items:
        if isinstance(sample, RosSample) and sample.gid is not None and sample.seq is not None:
            known = found.get(sample.gid)
            if known is None or sample.seq > known:
                found[sample.gid] = sample.seq
    if not found:
        return taken.marks
    return merge_marks(taken.marks, encode_marks(found.items()))


def _nothing(_delivery: Delivery, _linger_s: float) -> None:
    """Default ``on_appended``."""
