"""A Zenoh queryable whose queries are answered on a small thread pool.

Zenoh calls a queryable's handler on one of its own threads; an answer that takes the GIL for a
while (JSON, a mapping-table change) would hold that thread and every sample behind it. The
handler here only hands the query to the pool.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import zenoh


class PooledQueryable:
    """``start(session, key)`` declares the queryable; ``answer(query)`` runs on the pool and
    must reply and drop the query. ``stop()`` undeclares it and waits for answers under way."""

    def __init__(self, answer: Callable[[zenoh.Query], None], *, workers: int, name: str) -> None:
        self._answer = answer
        self._workers = workers
        self._name = name
        self._queryable: Any = None
        self._pool: ThreadPoolExecutor | None = None

    @property
    def running(self) -> bool:
        """Whether the queryable is declared (between ``start()`` and ``stop()``)."""
        return self._queryable is not None

    def start(self, session: zenoh.Session, key: str) -> None:
        """Start the pool and declare the queryable on ``key`` in ``session`` (no-op when running)."""
        if self._queryable is not None:
            return
        self._pool = ThreadPoolExecutor(max_workers=self._workers, thread_name_prefix=self._name)
        self._queryable = session.declare_queryable(key, self._on_query)

    def stop(self) -> None:
        """Undeclare the queryable, then wait for the answers under way and shut the pool down."""
        if self._queryable is not None:
            self._queryable.undeclare()
            self._queryable = None
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None

    def _on_query(self, query: zenoh.Query) -> None:
        pool = self._pool
        if pool is None:
            query.drop()
            return
        pool.submit(self._answer, query)
