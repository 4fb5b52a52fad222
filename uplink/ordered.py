"""Run jobs of one key in arrival order, jobs of different keys in parallel.

Batches of one edge stream must reach the producer in the order they arrived, or two batches
in flight at once could interleave a robot's records in Kafka. ``KeyedSerialExecutor`` keeps a
queue per key and lets at most one pool worker drain each queue.
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from collections.abc import Callable, Hashable
from concurrent.futures import Executor

log = logging.getLogger(__name__)


class KeyedSerialExecutor:
    """Runs jobs on ``pool``: those of one key one at a time in the order submitted, different keys in
    parallel."""

    def __init__(self, pool: Executor) -> None:
        self._pool = pool
        self._queues: dict[Hashable, deque[Callable[[], None]]] = {}
        self._lock = threading.Lock()

    def submit(self, key: Hashable, job: Callable[[], None]) -> None:
        """Run ``job`` on a pool worker after the jobs of ``key`` submitted before it."""
        with self._lock:
            queue = self._queues.get(key)
            if queue is not None:
                queue.append(job)  # a worker is draining this key: it will run the job in turn
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
            try:
                job()
            except Exception:  # the key's later jobs still run, in order
                log.exception("a job of %s failed", key)
