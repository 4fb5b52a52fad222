"""The hand-off from Zenoh callbacks to the processing thread: bounded, never blocking.

A Zenoh callback must return at once (a blocked callback stalls the session, and with it
discovery and every other subscription), so it only ``offer``\\ s the item: when the queue is at
``max_items`` or ``max_bytes`` the item is dropped and counted, and the back-pressure of a
full spool lands here, visibly, instead of in Zenoh. Control items (robot events) are ``force``\\ d
in: they are few and must not be lost.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass, fields
from typing import Generic, TypeVar

T = TypeVar("T")


@dataclass(slots=True)
class IntakeStats:
    offered: int = 0
    taken: int = 0
    dropped: int = 0
    dropped_bytes: int = 0
    queued: int = 0
    queued_bytes: int = 0
    high_water: int = 0

    def as_dict(self) -> dict[str, int]:
        return {f.name: getattr(self, f.name) for f in fields(self)}


class Intake(Generic[T]):
    """A bounded FIFO of ``(item, size)``; thread-safe."""

    def __init__(self, *, max_items: int = 100_000, max_bytes: int = 64 << 20) -> None:
        if max_items < 1 or max_bytes < 1:
            raise ValueError("intake bounds must be positive")
        self.max_items = max_items
        self.max_bytes = max_bytes
        self._items: deque[tuple[T, int]] = deque()
        self._bytes = 0
        self._cond = threading.Condition(threading.Lock())
        self._stats = IntakeStats()
        self._closed = False

    def offer(self, item: T, size: int = 0, *, force: bool = False) -> bool:
        """Queue ``item``; False (counted) when the queue is full or closed. Never blocks long."""
        with self._cond:
            stats = self._stats
            stats.offered += 1
            full = len(self._items) >= self.max_items or self._bytes + size > self.max_bytes
            if self._closed or (full and not force):
                stats.dropped += 1
                stats.dropped_bytes += size
                return False
            self._items.append((item, size))
            self._bytes += size
            stats.high_water = max(stats.high_water, len(self._items))
            if len(self._items) == 1:
                self._cond.notify()
            return True

    def take(self, max_items: int, timeout: float) -> list[T]:
        """Up to ``max_items`` items, waiting at most ``timeout`` s for the first one."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while not self._items:
                remaining = deadline - time.monotonic()
                if remaining <= 0 or self._closed:
                    return []
                self._cond.wait(remaining)
            out: list[T] = []
            while self._items and len(out) < max_items:
                item, size = self._items.popleft()
                self._bytes -= size
                out.append(item)
            self._stats.taken += len(out)
            return out

    def close(self) -> None:
        """Refuse new items (counted as dropped); queued ones can still be taken."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    def __len__(self) -> int:
        return len(self._items)

    def stats(self) -> IntakeStats:
        with self._cond:
            snap = IntakeStats(**self._stats.as_dict())
            snap.queued = len(self._items)
            snap.queued_bytes = self._bytes
            return snap
