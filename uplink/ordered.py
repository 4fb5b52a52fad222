"""Run jobs of one key in arrival order, jobs of different keys in parallel.

Batches of one edge stream must reach the producer in the order they arrived, or two batches
in flight at once could interleave a robot's records in Kafka. ``KeyedSerialExecutor`` keeps a
queue per key and lets at most one pool worker drain each queue. A job whose work is not
settled when it returns, and which the key's next job must not overtake (records on a second
producer), returns a ``Gate``: the key's next job runs once the gate opens, and no pool worker
waits meanwhile.
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from collections.abc import Callable, Hashable
from concurrent.futures import Executor

log = logging.getLogger(__name__)

Job = Callable[[], "Gate | None"]


class Gate:
    """Opened once by whoever settles a job's last part; then the job's key goes on."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._opened = False
        self._then: Callable[[], None] | None = None

    def open(self) -> None:
        """Let the key's next job run (only the first call counts)."""
        with self._lock:
            if self._opened:
                return
            self._opened = True
            then, self._then = self._then, None
        if then is not None:
            then()

    @property
    def opened(self) -> bool:
        """Whether ``open`` was called."""
        return self._opened

    def when_open(self, then: Callable[[], None]) -> None:
        """Call ``then`` once the gate is open (at once when it already is)."""
        with self._lock:
            if not self._opened:
                self._then = then
                return
        then()


class KeyedSerialExecutor:
    """Runs jobs on ``pool``: those of one key one at a time in the order submitted, different keys in
    parallel."""

    def __init__(self, pool: Executor) -> None:
        self._pool = pool
        self._queues: dict[Hashable, deque[Job]] = {}
        self._lock = threading.Lock()

    def submit(self, key: Hashable, job: Job) -> None:
        """Run ``job`` on a pool worker after the jobs of ``key`` submitted before it (and after the
        gate the last of them returned, if any, opened)."""
        with self._lock:
            queue = self._queues.get(key)
            if queue is not None:
                queue.append(job)  # a worker is draining this key (or it waits at a gate): in turn
                return
            self._queues[key] = deque([job])
        self._pool.submit(self._drain, key)

    def _drain(self, key: Hashable) -> None:
        while True:
            with self._lock:
                queue = self._queues[key]
                if not queue:
                    del self._queues[key]
                    return
                job = queue.popleft()
            gate = None
            try:
                gate = job()
            except Exception:  # the key's later jobs still run, in order
                log.exception("a job of %s failed", key)
            if gate is not None and not gate.opened:
                gate.when_open(lambda: self._resume(key))
                return  # the key stays queued: later jobs wait for the gate, not a worker

    def _resume(self, key: Hashable) -> None:
        try:
            self._pool.submit(self._drain, key)
        except RuntimeError:  # the pool shut down meanwhile: the key's jobs are not run
            log.debug("jobs of %s dropped: the executor is shut down", key)
