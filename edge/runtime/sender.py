"""The WAN sender: one thread per record buffer (stream), batches out, acknowledgements in.

Loop: read the next batch from the buffer (``read_unacked`` marks it in flight), encode it with
the schema of every fingerprint it uses, send it; when the uplink answers ``ok`` the batch is
``ack``\\ ed (it leaves the spool); on an ``error`` answer, no answer or a timeout it is
``release``\\ d (it will be read again, first) and sending pauses for a bounded, jittered,
exponential backoff, after which one batch probes the link before the full window of
``max_in_flight`` batches is used again. A partial batch leaves ``linger`` after the previous
batch of the stream (so at once when the stream was quiet that long): at a steady rate that is
one batch per ``linger`` as with a timer started by the first waiting record, but the first
records after a pause (or at start, where the uplink may have a schema to register) do not wait.
Records may bring their own, usually longer, linger (``pump(linger_s)``: a mapping's
``linger``, by default its aggregate window): the shortest one among the waiting records counts.

A batch carries the text of each schema its records use until the uplink has acknowledged a
batch that carried it; later batches list the fingerprint alone. An uplink that does not know a
left-out schema (it restarted, or it is another uplink) answers ``need_schemas``: the batch goes
again at once with those texts, without backoff, and they travel again until acknowledged.
One warning is logged when an outage starts and one line when it ends. Every answer says the
largest Kafka record the uplink produces; ``on_limit`` hears it (docs/images.md).
"""

from __future__ import annotations

import contextlib
import logging
import queue
import random
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, fields

from fleetlink.common.metrics.buckets import BucketCounts
from fleetlink.common.ratelimit import LogLimiter
from fleetlink.edge.config import WanSection
from fleetlink.edge.errors import SpoolError
from fleetlink.edge.runtime.backoff import Backoff
from fleetlink.edge.runtime.schema_book import SchemaBook
from fleetlink.edge.runtime.transport import Transport
from fleetlink.edge.spool import RecordBuffer, SpoolBatch
from fleetlink.wire import Codec, WireError, decode_ack, encode_batch_groups
from fleetlink.wire.groups import group_head

log = logging.getLogger(__name__)
_NS = 1_000_000_000


@dataclass(frozen=True, slots=True)
class SenderOptions:
    """How a ``WanSender`` batches, waits and retries (durations in seconds)."""

    batch_max_records: int = 2000
    batch_max_bytes: int = 1 << 20
    linger_s: float = 0.02
    ack_timeout_s: float = 10.0
    max_in_flight: int = 4
    backoff_min_s: float = 0.2
    backoff_max_s: float = 30.0
    codec: Codec = "zstd"

    @classmethod
    def from_wan(cls, wan: WanSection) -> SenderOptions:
        """From the config's ``wan:`` section (durations there are nanoseconds)."""
        return cls(
            batch_max_records=wan.batch_max_records,
            batch_max_bytes=int(wan.batch_max_bytes),
            linger_s=wan.linger / _NS,
            ack_timeout_s=wan.ack_timeout / _NS,
            max_in_flight=wan.max_in_flight,
            backoff_min_s=wan.retry_backoff_min / _NS,
            backoff_max_s=wan.retry_backoff_max / _NS,
            codec=wan.codec,
        )


@dataclass(slots=True)
class SenderStats:
    """One sender's running totals of batches, records, bytes, schemas and outages."""

    batches_sent: int = 0
    batches_acked: int = 0
    batches_retried: int = 0
    records_sent: int = 0
    records_acked: int = 0
    records_dead_lettered: int = 0
    """Records the uplink could not produce and wrote to the dead-letter topic instead."""
    bytes_sent: int = 0
    stale_acks: int = 0
    missing_schemas: int = 0
    schemas_elided: int = 0
    """Schema texts left out of batches because an uplink had acknowledged them."""
    schema_requests: int = 0
    """Batches an uplink answered with ``need_schemas`` (sent again with the texts)."""
    batches_held_back: int = 0
    """Batches an uplink held back behind an earlier one that it did not produce (sent again after it)."""
    outages: int = 0
    in_flight: int = 0

    def as_dict(self) -> dict[str, int]:
        """The counters by field name."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass(slots=True)
class _Flight:
    first_seq: int
    last_seq: int
    records: int
    sent_at: float
    carried: frozenset[bytes]
    """Fingerprints whose schema text the batch carried."""
    elided: frozenset[bytes]
    """Fingerprints the batch used without their text."""


def answer_wakes(
    *,
    failed: bool,
    asleep_until: float | None,
    arrived: float,
    linger_s: float,
    window_full: bool,
    stopping: bool,
) -> bool:
    """Whether an answer that ``arrived`` must wake the sender's thread, or may wait for the wake-up
    it has planned (``asleep_until``; ``None``: it is awake, or about to decide how long to sleep).
    It may wait only for a planned wake-up within ``linger_s`` while nothing else needs it: not a
    ``failed`` batch without an answer (its retry and backoff start at once), not a full window
    (the answer frees a place), not a stop (it waits for the answers in flight)."""
    if failed or window_full or stopping or asleep_until is None:
        return True
    return asleep_until > arrived + linger_s


class WanSender:
    """Sends one buffer's records to the uplink. ``start()`` / ``stop()``; thread-safe ``wake()``."""

    def __init__(
        self,
        buffer: RecordBuffer,
        transport: Transport,
        schemas: SchemaBook,
        *,
        site: str,
        edge_id: str,
        options: SenderOptions | None = None,
        clock: Callable[[], float] = time.monotonic,
        rng: random.Random | None = None,
        on_limit: Callable[[int], object] | None = None,
        origin: int = 0,
    ) -> None:
        self.buffer = buffer
        self.origin = origin
        """Non-zero: every batch asks for exactly-once delivery under this origin (the spool's)."""
        self._on_limit = on_limit
        """Hears the uplink's record limit from every answer (``edge.runtime.limits.RecordLimit``)."""
        self.transport = transport
        self.schemas = schemas
        self.site = site
        self.edge_id = edge_id
        self.options = options or SenderOptions()
        self._clock = clock
        self._backoff = Backoff(self.options.backoff_min_s, self.options.backoff_max_s, rng=rng)
        self._wakes: queue.SimpleQueue[None] = queue.SimpleQueue()
        self._replies: deque[tuple[int, bytes | None, str | None, float]] = deque()
        """Answers not handled yet: ``(first_seq, reply, error, arrived)`` (``_reply``)."""
        self._in_flight: dict[int, _Flight] = {}
        self._retry_at = 0.0
        self._healthy = True
        self._last_send = float("-inf")
        self._due: float | None = None
        self._asleep_until: float | None = None
        """Until when the sender's thread sleeps (None: it is awake, or about to decide)."""
        """When the waiting records may leave as a partial batch, if some brought their linger."""
        self._known: set[bytes] = set()
        """Fingerprints whose schema an uplink acknowledged (left out of later batches)."""
        self._outage_since: float | None = None
        self.ack_latency = BucketCounts()
        """From sending each acknowledged batch to its ack (``fleetlink_wan_ack_latency_seconds``)."""
        self._last_error = ""
        self._stopping = threading.Event()
        self._mutex = threading.Lock()
        """Guards the state above: the sender's thread and ``pump`` (another thread) both send."""
        self._closed = False
        self._stop_deadline = 0.0
        self._thread: threading.Thread | None = None
        self._limiter = LogLimiter(log)
        self.stats = SenderStats()

    @property
    def stream(self) -> str:
        """The name of the buffer's stream."""
        return self.buffer.stream

    # -- lifecycle -------------------------------------------------------------------------------
    def start(self) -> WanSender:
        """Start the sender's thread (once); returns ``self``."""
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name=f"wan-{self.stream}", daemon=True)
            self._thread.start()
        return self

    def stop(self, timeout_s: float = 5.0) -> None:
        """Send what can be sent within ``timeout_s`` (in-flight batches get their answer), then
        stop; whatever is left stays in the buffer (released, so it is read again first)."""
        self.request_stop(timeout_s)
        self.join()

    def request_stop(self, timeout_s: float) -> None:
        """Begin stopping (see ``stop``) without waiting: stop several senders in parallel."""
        self._stop_deadline = self._clock() + timeout_s
        self._stopping.set()
        self.wake()

    def join(self) -> None:
        """Wait for the sender's thread to end, up to 2 s past the stop deadline set by ``request_stop``."""
        thread = self._thread
        if thread is not None:
            thread.join(max(0.0, self._stop_deadline - self._clock()) + 2.0)
            self._thread = None

    def wake(self) -> None:
        """New records were appended (or something changed): look again now."""
        self._wakes.put(None)

    def pump(self, linger_s: float | None = None) -> None:
        """Send the full batches that can go now, from the calling thread (the processing thread,
        right after appending), then wake the sender's own thread for the rest. ``linger_s``: how
        long the records just appended may wait for company (``None``: ``options.linger_s``).

        Measured: with eight receiver threads draining a burst, the sender's thread waited up to
        0.3 s for the GIL while full batches piled up; the appending thread holds it already.
        Partial batches (``linger``), answers, retries and backoff stay with the sender's thread.
        """
        due = self._last_send + (self.options.linger_s if linger_s is None else linger_s)
        current = self._due
        if current is None or due < current:
            self._due = due
        else:
            due = current
        if self._mutex.acquire(blocking=False):  # else the sender's thread is at it
            try:
                self._handle_replies()
                while (
                    not self._closed
                    and self._clock() >= self._retry_at
                    and (
                        len(self._in_flight) < self._window()
                        and self._unsent() >= self.options.batch_max_records
                    )
                ):
                    batch = self.buffer.read_unacked(
                        self.options.batch_max_records, self.options.batch_max_bytes
                    )
                    if batch is None:
                        break
                    self._last_send = self._clock()
                    self._send(batch)
                    self._handle_replies()  # a send that failed at once sets the backoff now
            except SpoolError as exc:  # closed under us: the sender's thread winds down
                log.debug("sender %s: pump stops: %s", self.stream, exc)
            finally:
                self._mutex.release()
        # The sender's thread sleeps until a deadline it set: if that comes before the records
        # just appended are due, it will see them in time; waking it for every append (hundreds
        # of times a second at fleet rates) would cost a thread switch each for nothing.
        asleep_until = self._asleep_until
        if asleep_until is None or due < asleep_until or self._unsent() >= self.options.batch_max_records:
            self.wake()

    def __enter__(self) -> WanSender:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    @property
    def outage_s(self) -> float:
        """Seconds since the current outage began; 0.0 while the link works."""
        since = self._outage_since
        return 0.0 if since is None else self._clock() - since

    @property
    def last_error(self) -> str:
        """The reason the last batch failed (empty before any failure)."""
        return self._last_error

    # -- the loop --------------------------------------------------------------------------------
    def _run(self) -> None:
        try:
            self._loop()
        except SpoolError as exc:  # the buffer was closed under us: nothing more to do
            log.debug("sender %s stops: %s", self.stream, exc)
        finally:
            with self._mutex:
                self._closed = True
                if self._in_flight:
                    with contextlib.suppress(SpoolError):
                        self.buffer.release_all()
                    self._in_flight.clear()
                self.stats.in_flight = 0

    def _loop(self) -> None:
        idle = max(0.05, self.options.linger_s)
        while True:
            with self._mutex:
                self._handle_replies()
                now = self._clock()
                if self._stopping.is_set() and (
                    now >= self._stop_deadline or (not self._in_flight and not self._unsent())
                ):
                    return
                wait_until: float | None = None
                if now < self._retry_at:
                    wait_until = self._retry_at
                elif len(self._in_flight) < self._window():
                    batch, wait_until = self._next_batch(now)
                    if batch is not None:
                        self._send(batch)
                        continue
                if wait_until is None and now < self._last_send + self.options.linger_s:
                    # Records appended from now on are due then: at a steady rate they are there
                    # by that time, and ``pump`` need not wake this thread for them.
                    wait_until = self._last_send + self.options.linger_s
                timeout = idle if wait_until is None else max(0.0, wait_until - now)
                if self._stopping.is_set():
                    timeout = min(timeout, max(0.0, self._stop_deadline - now))
                self._asleep_until = now + timeout
            self._wait(timeout)
            self._asleep_until = None

    def _window(self) -> int:
        return self.options.max_in_flight if self._healthy else 1

    def _unsent(self) -> int:
        return self.buffer.unsent()

    def _next_batch(self, now: float) -> tuple[SpoolBatch | None, float | None]:
        unsent = self._unsent()
        if unsent <= 0:
            return None, None
        if unsent < self.options.batch_max_records and not self._stopping.is_set():
            due = self._due
            if due is None:
                due = self._last_send + self.options.linger_s
            if now < due:
                return None, due
        batch = self.buffer.read_unacked(self.options.batch_max_records, self.options.batch_max_bytes)
        if batch is not None:
            self._last_send = now
        return batch, None

    def _wait(self, timeout: float) -> None:
        """Sleep up to ``timeout`` seconds or until woken (every wake-up pending is taken)."""
        try:
            self._wakes.get(timeout=timeout) if timeout > 0 else self._wakes.get_nowait()
        except queue.Empty:
            return
        with contextlib.suppress(queue.Empty):
            while True:
                self._wakes.get_nowait()

    def _reply(self, first_seq: int, reply: bytes | None, error: str | None) -> None:
        """An answer (or a failure) for the batch ``first_seq``, on the transport's thread. It waits
        in ``_replies`` for the sender's thread when that thread wakes within ``linger`` anyway
        (at a steady rate it sleeps until the next batch is due) and the window has room: one
        thread switch a batch, not two. No answer (a timeout, a send that failed), a full window,
        a long sleep or a stop wake it; an answer that refuses the batch is read (and the batch
        released for its retry) at that wake-up, at most ``linger`` later."""
        arrived = self._clock()
        self._replies.append((first_seq, reply, error, arrived))
        if answer_wakes(
            failed=error is not None,
            asleep_until=self._asleep_until,
            arrived=arrived,
            linger_s=self.options.linger_s,
            window_full=len(self._in_flight) >= self._window(),
            stopping=self._stopping.is_set(),
        ):
            self._wakes.put(None)

    def _handle_replies(self) -> None:
        """Apply the answers that came (the mutex held)."""
        replies = self._replies
        while replies:
            self._complete(*replies.popleft())

    # -- one batch -------------------------------------------------------------------------------
    def _send(self, batch: SpoolBatch) -> None:
        self._due = None
        fps: set[bytes] = set()
        for group in batch.groups:
            fps.update(group_head(group.group)[1])
        elided = fps & self._known
        schemas, missing = self.schemas.lookup(fps - elided if elided else fps)
        if missing:
            self.stats.missing_schemas += len(missing)
            self._limiter.log(
                logging.WARNING,
                "missing-schema",
                "stream %s: no schema known for fingerprint(s) %s; the uplink will dead-letter those records",
                self.stream,
                ", ".join(m.hex() for m in missing),
            )
        try:
            data = encode_batch_groups(
                site=self.site,
                edge_id=self.edge_id,
                stream=self.stream,
                origin=self.origin,
                acked=batch.acked,
                groups=[(g.first_seq, g.group) for g in batch.groups],
                schemas=schemas,
                elided=elided,
                codec=self.options.codec,
            )
        except WireError as exc:  # cannot happen for what the spool hands out; never loop on it
            log.error(
                "stream %s: cannot encode batch %d..%d: %s", self.stream, batch.first_seq, batch.last_seq, exc
            )
            self.buffer.release(batch.first_seq)
            self._failed(f"batch encoding: {exc}")
            return
        self._in_flight[batch.first_seq] = _Flight(
            batch.first_seq,
            batch.last_seq,
            batch.count,
            self._clock(),
            frozenset(schemas),
            frozenset(elided),
        )
        stats = self.stats
        stats.schemas_elided += len(elided)
        stats.batches_sent += 1
        stats.records_sent += batch.count
        stats.bytes_sent += len(data)
        stats.in_flight = len(self._in_flight)
        first = batch.first_seq

        def done(reply: bytes | None, error: str | None) -> None:
            self._reply(first, reply, error)

        try:
            self.transport.send(data, self.options.ack_timeout_s, done)
        except Exception as exc:  # noqa: BLE001 - a closed session or a Zenoh error: retry later
            done(None, f"send failed: {exc}")

    def _complete(self, first_seq: int, reply: bytes | None, error: str | None, arrived: float) -> None:
        flight = self._in_flight.pop(first_seq, None)
        self.stats.in_flight = len(self._in_flight)
        if flight is None:
            return
        if reply is not None:
            error = self._accept(flight, reply, arrived)
        if error is not None:
            self.buffer.release(first_seq)
            self._failed(error)

    def _accept(self, flight: _Flight, reply: bytes, arrived: float) -> str | None:
        """Apply an acknowledgement; returns why the batch must be sent again, if it must."""
        try:
            ack = decode_ack(reply)
        except WireError as exc:
            return f"unreadable acknowledgement: {exc}"
        if self._on_limit is not None and ack.max_record_bytes:
            self._on_limit(ack.max_record_bytes)
        if (ack.edge_id, ack.stream, ack.first_seq, ack.last_seq) != (
            self.edge_id,
            self.stream,
            flight.first_seq,
            flight.last_seq,
        ):
            return (
                f"acknowledgement for {ack.edge_id}/{ack.stream} {ack.first_seq}..{ack.last_seq} "
                f"does not match batch {flight.first_seq}..{flight.last_seq}"
            )
        if ack.status == "need_schemas":
            return self._resend_with_schemas(flight, ack.missing_schemas)
        if ack.status == "held_back":
            self._held_back(flight)
            return None
        if ack.status != "ok":
            return f"uplink: {ack.detail or 'batch not produced'}"
        self._known.update(flight.carried)
        if not self.buffer.ack(flight.first_seq):
            self.stats.stale_acks += 1
        stats = self.stats
        stats.batches_acked += 1
        stats.records_acked += flight.records
        self.ack_latency.observe(arrived - flight.sent_at)
        dead = sum(1 for f in ack.failures if f.dead_lettered)
        if dead:
            stats.records_dead_lettered += dead
            self._limiter.log(
                logging.WARNING,
                "dead-lettered",
                "stream %s: the uplink dead-lettered %d record(s) of batch %d..%d: %s",
                self.stream,
                dead,
                flight.first_seq,
                flight.last_seq,
                ack.failures[0].reason,
            )
        self._succeeded()
        return None

    def _resend_with_schemas(self, flight: _Flight, asked: tuple[bytes, ...]) -> str | None:
        """The uplink lacks schemas the batch left out: forget that they were acknowledged and
        send the batch again now (no backoff: nothing is wrong with the link)."""
        unexpected = [fp for fp in asked if fp not in flight.elided]
        if unexpected:  # the batch carried them, or never used them: retry like an error
            names = ", ".join(fp.hex() for fp in unexpected)
            return f"uplink asks for schemas the batch did not leave out: {names}"
        self._known.difference_update(asked)
        self.stats.schema_requests += 1
        self.buffer.release(flight.first_seq)
        log.info(
            "stream %s: the uplink asks for %d schema(s) again (restarted, or another uplink); "
            "batch %d..%d goes again with them",
            self.stream,
            len(asked),
            flight.first_seq,
            flight.last_seq,
        )
        return None

    def _held_back(self, flight: _Flight) -> None:
        """The uplink holds the batch back behind an earlier one of the stream that it did not
        produce: send it again after that one. The earlier batch's own answer brings the backoff
        (this one adds no step of its own); meanwhile one batch at a time, at the earliest after
        the shortest backoff."""
        self.stats.batches_held_back += 1
        self.buffer.release(flight.first_seq)
        self._healthy = False
        self._retry_at = max(self._retry_at, self._clock() + self._backoff.min_s)

    def _succeeded(self) -> None:
        if self._outage_since is not None:
            log.warning(
                "stream %s: the uplink acknowledges again after %.1f s (%d batch(es) retried)",
                self.stream,
                self._clock() - self._outage_since,
                self.stats.batches_retried,
            )
        self._outage_since = None
        self._healthy = True
        self._backoff.reset()

    def _failed(self, error: str) -> None:
        now = self._clock()
        self.stats.batches_retried += 1
        self._last_error = error
        self._healthy = False
        self._retry_at = max(self._retry_at, now + self._backoff.next_delay())
        if self._outage_since is None:
            self._outage_since = now
            self.stats.outages += 1
            log.warning(
                "stream %s: batch not acknowledged (%s); records stay in the buffer and are "
                "retried with backoff (up to %g s)",
                self.stream,
                error,
                self.options.backoff_max_s,
            )
        else:
            self._limiter.log(logging.DEBUG, "retry", "stream %s: still failing: %s", self.stream, error)

    def snapshot(self) -> dict[str, object]:
        """The counters with the link's health, the current outage (seconds), the last error and the ack
        latency."""
        return {
            **self.stats.as_dict(),
            "healthy": self._healthy,
            "outage_s": round(self.outage_s, 3),
            "last_error": self._last_error,
            "ack_latency": self.ack_latency.totals().as_dict(),
        }
