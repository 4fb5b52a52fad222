"""The hand-off from the receivers to the processing thread: bounded, never blocking Zenoh.

A Zenoh callback must return at once (a blocked callback stalls the session, and with it
discovery and every other subscription), so it only ``offer``\\ s the item: when the queue is at
``max_items`` or ``max_bytes`` the item is dropped and counted. Control items (robot events) are
``force``\\ d in: they are few and must not be lost.

A receiver's drain thread is not a Zenoh thread: ``offer_many(pairs, wait_s=...)`` waits up to
``wait_s`` for room, while the samples behind it stay in the subscription's Rust-side ring (no
Python objects, no GIL). So a burst larger than the intake is absorbed by the rings instead of
being dropped here, and the receivers stop competing with the processing thread for the GIL
while it catches up. What still does not fit after the wait is dropped and counted, as is what
a ring overflows (sequence gaps): the back-pressure of a full spool stays visible.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, fields
from typing import Generic, TypeVar

T = TypeVar("T")


@dataclass(slots=True)
class IntakeStats:
    """An ``Intake``'s running totals (items and bytes) and what it holds now."""

    offered: int = 0
    taken: int = 0
    dropped: int = 0
    dropped_bytes: int = 0
    queued: int = 0
    queued_bytes: int = 0
    high_water: int = 0

    def as_dict(self) -> dict[str, int]:
        """The counters by field name."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


class Intake(Generic[T]):
    """A bounded FIFO of ``(item, size)``; thread-safe.

    The offering side runs once per received sample, so it is kept to one plain lock (a C-level
    ``with``), plain integer counters and a wake-up only when the queue was empty.
    """

    def __init__(self, *, max_items: int = 100_000, max_bytes: int = 64 << 20) -> None:
        if max_items < 1 or max_bytes < 1:
            raise ValueError("intake bounds must be positive")
        self.max_items = max_items
        self.max_bytes = max_bytes
        self._items: deque[tuple[T, int]] = deque()
        self._bytes = 0
        self._lock = threading.Lock()
        self._cond = threading.Condition(self._lock)
        self._room = threading.Condition(self._lock)
        self._waiting = 0
        self._offered = self._taken = self._dropped = self._dropped_bytes = self._high_water = 0
        self._closed = False

    def offer(self, item: T, size: int = 0, *, force: bool = False) -> bool:
        """Queue ``item``; False (counted) when the queue is full or closed. Never blocks long."""
        with self._lock:
            self._offered += 1
            items = self._items
            if self._closed or (
                (len(items) >= self.max_items or self._bytes + size > self.max_bytes) and not force
            ):
                self._dropped += 1
                self._dropped_bytes += size
                return False
            items.append((item, size))
            self._bytes += size
            n = len(items)
            self._high_water = max(self._high_water, n)
            if n == 1:
                self._cond.notify()
            return True

    def offer_many(self, pairs: Sequence[tuple[T, int]], *, wait_s: float = 0.0) -> int:
        """Queue ``(item, size)`` pairs in order under one lock, while they fit, after waiting up
        to ``wait_s`` for room for all of them; the rest are dropped (counted). Returns how many
        were queued."""
        with self._lock:
            if wait_s > 0 and not self._fits(pairs):
                deadline = time.monotonic() + wait_s
                self._waiting += 1
                try:
                    while not self._closed and not self._fits(pairs):
                        remaining = deadline - time.monotonic()
                        if remaining <= 0:
                            break
                        self._room.wait(remaining)
                finally:
                    self._waiting -= 1
            items = self._items
            before = len(items)
            self._offered += len(pairs)
            room = 0 if self._closed else self.max_items - before
            nbytes = self._bytes
            taken = 0
            for pair in pairs:
                if taken >= room or nbytes + pair[1] > self.max_bytes:
                    break
                nbytes += pair[1]
                taken += 1
            if taken < len(pairs):
                self._dropped += len(pairs) - taken
                self._dropped_bytes += sum(size for _item, size in pairs[taken:])
            items.extend(pairs[:taken] if taken < len(pairs) else pairs)
            self._bytes = nbytes
            self._high_water = max(self._high_water, before + taken)
            if before == 0 and taken:
                self._cond.notify()
            return taken

    def _fits(self, pairs: Sequence[tuple[T, int]]) -> bool:
        return (
            len(self._items) + len(pairs) <= self.max_items
            and self._bytes + sum(size for _item, size in pairs) <= self.max_bytes
        )

    def take(self, max_items: int, timeout: float) -> list[T]:
        """Up to ``max_items`` items, waiting at most ``timeout`` s for the first one."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while not self._items:
                remaining = deadline - time.monotonic()
                if remaining <= 0 or self._closed:
                    return []
                self._cond.wait(remaining)
            items = self._items
            if len(items) <= max_items:  # all of it: swap the queue, sort it out after the lock
                self._items, self._bytes = deque(), 0
                self._taken += len(items)
            else:
                taken_bytes = 0
                chunk: deque[tuple[T, int]] = deque()
                for _ in range(max_items):
                    pair = items.popleft()
                    taken_bytes += pair[1]
                    chunk.append(pair)
                self._bytes -= taken_bytes
                self._taken += max_items
                items = chunk
            if self._waiting:
                self._room.notify_all()
        return [item for item, _size in items]

    def close(self) -> None:
        """Refuse new items (counted as dropped); queued ones can still be taken."""
        with self._cond:
            self._closed = True
            self._cond.notify_all()
            self._room.notify_all()

    def __len__(self) -> int:
        return len(self._items)

    def stats(self) -> IntakeStats:
        """A consistent copy of the counters and of what is queued now."""
        with self._lock:
            return IntakeStats(
                offered=self._offered,
                taken=self._taken,
                dropped=self._dropped,
                dropped_bytes=self._dropped_bytes,
                queued=len(self._items),
                queued_bytes=self._bytes,
                high_water=self._high_water,
            )
