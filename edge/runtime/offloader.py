"""The uploader of claim-checked payloads: worker threads putting objects, in order per lane.

``submit`` (the processing thread) queues a ``ClaimJob``; a worker puts its object (the same
key and bytes when tried again: idempotent) and hands the result back with ``post`` (the
processor's control queue), where the record is made and appended to the spool. So a record
that refers to an object enters the spool only once the object is stored: from the spool on,
the at-least-once guarantee covers the object too.

* **Order**: every job of a lane (a robot's records of one mapping) goes to the same worker, in
  order, and a record whose payload stays inline waits behind its lane's uploads (one with
  nothing ahead of it comes back from ``submit`` at once).
* **Store down or slow** (no answer, 5xx, 429, a timeout): the worker tries the same object
  again after a bounded, jittered backoff; its jobs wait. One warning when an outage starts, one
  line when it ends.
* **Store refusing** (403, 404 no bucket, 400 ...): the job comes back with the error and the
  record becomes a dead letter (stage ``claim_check``).
* **Bounded**: at most ``max_pending_bytes`` of payloads wait; a job beyond it is refused at once
  (a dead letter), so a long outage costs memory up to that bound and never stops the edge.
* **Stopping**: ``stop`` lets the workers finish for up to its timeout; jobs still waiting are
  handed back as errors (dead letters, counted in ``abandoned``).
"""

from __future__ import annotations

import logging
import random
import threading
import time
import zlib
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import Protocol

from fleetlink.common.objects import ObjectStoreError
from fleetlink.common.ratelimit import LogLimiter
from fleetlink.edge.claim_check import Claimed, ClaimJob, ObjectRef, Upload
from fleetlink.edge.runtime.backoff import Backoff

log = logging.getLogger(__name__)


class Store(Protocol):
    """What the uploader needs of an object store (``fleetlink.common.objects.ObjectStore``)."""

    bucket: str

    def put(self, key: str, data: bytes, *, content_type: str, sha256_hex: str | None = None) -> object:
        """Store ``data`` under ``key``; raises ``ObjectStoreError`` (``retriable`` when trying again may
        succeed)."""
        ...

    def url_of(self, key: str) -> str:
        """The URL a record gives for the object at ``key``."""
        ...


@dataclass(slots=True)
class OffloadStats:
    """The uploader's running totals, and what waits for upload now."""

    uploaded: int = 0
    uploaded_bytes: int = 0
    passed: int = 0
    """Jobs without an upload (inline payloads) that waited behind their lane's uploads."""
    retries: int = 0
    """Attempts that failed and were tried again (the store was down or slow)."""
    refused: int = 0
    """Objects the store refused (dead-lettered)."""
    full: int = 0
    """Jobs refused because ``max_pending_bytes`` of payloads were already waiting (dead-lettered)."""
    abandoned: int = 0
    """Jobs still waiting when the edge stopped (dead-lettered)."""
    pending: int = 0
    pending_bytes: int = 0
    outages: int = 0

    def as_dict(self) -> dict[str, int]:
        """The counters by field name."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


class Offloader:
    """Uploads claim-checked payloads on worker threads, in order per lane, retrying with backoff while the
    store is down; hands every result back through ``post``."""

    def __init__(
        self,
        store: Store,
        post: Callable[[Claimed], object],
        *,
        workers: int = 4,
        max_pending_bytes: int = 256 << 20,
        backoff_min_s: float = 0.2,
        backoff_max_s: float = 30.0,
        clock: Callable[[], float] = time.monotonic,
        rng: random.Random | None = None,
    ) -> None:
        self.store = store
        self._post = post
        self.max_pending_bytes = max_pending_bytes
        self._backoff = (backoff_min_s, backoff_max_s)
        self._clock = clock
        self._rng = rng or random.Random()
        self._lock = threading.Lock()
        self._queues: list[deque[ClaimJob]] = [deque() for _ in range(workers)]
        self._ready = [threading.Condition(self._lock) for _ in range(workers)]
        self._lanes: dict[str, int] = {}
        """Jobs waiting per lane (lanes with none are not kept)."""
        self._threads: list[threading.Thread] = []
        self._stopping = threading.Event()
        self._closed = False
        self._outage_since: float | None = None
        self.last_error = ""
        self._limiter = LogLimiter(log)
        self.stats = OffloadStats()

    # -- lifecycle -------------------------------------------------------------------------------
    def start(self) -> Offloader:
        """Start the worker threads (once); returns ``self``."""
        if not self._threads:
            for index in range(len(self._queues)):
                thread = threading.Thread(
                    target=self._run, args=(index,), name=f"offload-{index}", daemon=True
                )
                thread.start()
                self._threads.append(thread)
        return self

    def stop(self, timeout_s: float = 5.0) -> None:
        """Finish what waits within ``timeout_s``; hand back the rest as errors."""
        deadline = self._clock() + timeout_s
        with self._lock:
            self._closed = True
            for ready in self._ready:
                ready.notify_all()
        for thread in self._threads:
            thread.join(max(0.0, deadline - self._clock()))
        self._stopping.set()
        with self._lock:
            for ready in self._ready:
                ready.notify_all()
        for thread in self._threads:
            thread.join(2.0)
        self._threads = []
        left: list[ClaimJob] = []
        with self._lock:
            for queue in self._queues:
                left.extend(queue)
                queue.clear()
            self._lanes.clear()
            self.stats.pending = self.stats.pending_bytes = 0
        if left:
            self.stats.abandoned += len(left)
            log.warning(
                "object store: %d payload(s) not uploaded by the end of the stop: dead-lettered", len(left)
            )
        for job in left:
            self._post(Claimed(job, error="the edge stopped before the payload was uploaded"))

    @property
    def outage_s(self) -> float:
        """Seconds since uploads began failing; 0.0 while the store takes them."""
        since = self._outage_since
        return 0.0 if since is None else self._clock() - since

    def snapshot(self) -> dict[str, object]:
        """The counters with the current outage (seconds) and the last upload error."""
        with self._lock:
            return {
                **self.stats.as_dict(),
                "outage_s": round(self.outage_s, 3),
                "last_error": self.last_error,
            }

    # -- the processing thread -------------------------------------------------------------------
    def submit(self, job: ClaimJob) -> Claimed | None:
        """Queue ``job`` on its lane's worker; returns ``None`` when queued, else its result now: a job
        without upload and nothing ahead of it in its lane, or an error when the edge is stopping or
        ``max_pending_bytes`` of payloads already wait."""
        with self._lock:
            if self._closed:
                return Claimed(job, error="the edge is stopping: the payload was not uploaded")
            waiting = self._lanes.get(job.lane, 0)
            if job.upload is None and waiting == 0:
                return Claimed(job)
            stats = self.stats
            if job.upload is not None and stats.pending_bytes + job.size > self.max_pending_bytes:
                stats.full += 1
                self._limiter.log(
                    logging.WARNING,
                    "full",
                    "object store: %d bytes of payloads wait for upload already (objects.max_pending_bytes); "
                    "records are dead-lettered until the store takes them (%s)",
                    stats.pending_bytes,
                    self.last_error or "uploads are slower than the payloads arrive",
                )
                return Claimed(
                    job,
                    error=f"object store backlog full: {stats.pending_bytes} bytes wait for upload "
                    f"(objects.max_pending_bytes {self.max_pending_bytes}); last error: "
                    f"{self.last_error or 'none'}",
                )
            index = zlib.crc32(job.lane.encode("utf-8")) % len(self._queues)
            self._queues[index].append(job)
            self._lanes[job.lane] = waiting + 1
            stats.pending += 1
            stats.pending_bytes += job.size
            self._ready[index].notify()
        return None

    # -- the workers -----------------------------------------------------------------------------
    def _run(self, index: int) -> None:
        queue, ready = self._queues[index], self._ready[index]
        backoff = Backoff(*self._backoff, rng=random.Random(self._rng.random()))
        while True:
            with self._lock:
                while not queue and not self._closed:
                    ready.wait()
                if not queue:
                    return
                job = queue[0]
            result = self._attempt(job, backoff)
            if result is None:  # the store is down: wait, then the same job again
                if self._stopping.wait(backoff.next_delay()):
                    return
                continue
            with self._lock:
                if not queue or queue[0] is not job:  # stop took it meanwhile
                    return
                queue.popleft()
                left = self._lanes.get(job.lane, 1) - 1
                if left:
                    self._lanes[job.lane] = left
                else:
                    self._lanes.pop(job.lane, None)
                self.stats.pending -= 1
                self.stats.pending_bytes -= job.size
            self._post(result)

    def _attempt(self, job: ClaimJob, backoff: Backoff) -> Claimed | None:
        """The job's result, or None when it is to be tried again."""
        upload = job.upload
        if upload is None:
            with self._lock:
                self.stats.passed += 1
            return Claimed(job)
        try:
            self.store.put(
                upload.key, upload.data, content_type=upload.content_type, sha256_hex=upload.sha256
            )
        except ObjectStoreError as exc:
            self.last_error = str(exc)
            if exc.retriable:
                self._failing(str(exc))
                return None
            with self._lock:
                self.stats.refused += 1
            self._limiter.log(logging.WARNING, "refused", "object store refused %s: %s", upload.key, exc)
            return Claimed(job, error=f"object store refused the payload: {exc}")
        self._succeeded(backoff)
        with self._lock:
            self.stats.uploaded += 1
            self.stats.uploaded_bytes += len(upload.data)
        return Claimed(job, ref=self._ref(upload))

    def _ref(self, upload: Upload) -> ObjectRef:
        return ObjectRef(
            url=self.store.url_of(upload.key),
            bucket=self.store.bucket,
            key=upload.key,
            size=len(upload.data),
            sha256=upload.sha256,
            content_type=upload.content_type,
        )

    def _failing(self, error: str) -> None:
        with self._lock:
            self.stats.retries += 1
            if self._outage_since is not None:
                return
            self._outage_since = self._clock()
            self.stats.outages += 1
        log.warning(
            "object store: upload failed (%s); payloads wait (up to objects.max_pending_bytes) and are "
            "tried again with backoff",
            error,
        )

    def _succeeded(self, backoff: Backoff) -> None:
        backoff.reset()
        with self._lock:
            since = self._outage_since
            self._outage_since = None
        if since is not None:
            log.warning("object store: uploads succeed again after %.1f s", self._clock() - since)
