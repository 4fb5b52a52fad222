"""After a batch of an edge stream fails, its later batches wait for it: a robot's order holds.

An at-least-once stream has several batches in flight. When one is not produced (answered
``error``: a record must be retried, the registry did not answer, Kafka refused it for now;
``need_schemas``; or "busy", unread) and a later one is, the failed one comes again after it and
the robot's records reach Kafka out of order. ``StreamFence`` remembers the first seq of the
earliest failed batch of each stream; a later batch of that stream (a higher first seq) is
answered ``held_back`` without being produced, until the failed batch comes again (first seq at
or below it, arrived after the fence was set: an earlier batch already in hand when it was set
goes, and leaves the fence up). The edge sends again what was refused, in order, from the lowest
unacknowledged seq.

A fence lasts at most ``hold_s``: an edge that never sends the failed batch again (its spool
dropped those records, or it lost them) is not stopped for good. At most ``max_streams`` fences
are kept (the oldest go first, except for a fence that may not push others out).
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Hashable
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class Fenced:
    """Why a batch must wait: the earlier batch of its stream that failed."""

    failed_seq: int
    age_s: float


class StreamFence:
    """Per stream, the earliest failed batch that later batches must not overtake."""

    def __init__(
        self, hold_s: float = 60.0, *, max_streams: int = 10_000, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.hold_s = hold_s
        self.max_streams = max_streams
        self._clock = clock
        self._failed: dict[Hashable, tuple[int, float]] = {}
        self._lock = threading.Lock()

    def failed(self, stream: Hashable, first_seq: int, *, evict: bool = True) -> None:
        """The batch of ``stream`` starting at ``first_seq`` was not (wholly) produced. With
        ``evict`` false, a new fence that finds ``max_streams`` kept is not set rather than push
        out another stream's (a fence from a batch nobody has checked yet)."""
        now = self._clock()
        with self._lock:
            held = self._failed.get(stream)
            if held is not None and held[0] <= first_seq and now - held[1] <= self.hold_s:
                return
            if held is None and not evict and len(self._failed) >= self.max_streams:
                return
            self._failed.pop(stream, None)
            self._failed[stream] = (first_seq, now)
            while len(self._failed) > self.max_streams:
                del self._failed[next(iter(self._failed))]

    def check(self, stream: Hashable, first_seq: int, arrived: float | None = None) -> Fenced | None:
        """``None`` when the batch of ``stream`` starting at ``first_seq`` may be produced (the failed
        batch itself, an earlier one, or no fence); else why it must wait. ``arrived`` (this
        clock): when the batch came; one that came before the fence was set goes if it is not
        later than the failed batch, but is not that batch again, and leaves the fence up."""
        with self._lock:
            held = self._failed.get(stream)
            if held is None:
                return None
            seq, since = held
            age = self._clock() - since
            if first_seq <= seq:
                if arrived is None or arrived >= since:
                    del self._failed[stream]  # the failed batch is here again
                return None
            if age > self.hold_s:
                del self._failed[stream]  # it waited for long enough
                return None
            return Fenced(seq, age)

    def __len__(self) -> int:
        return len(self._failed)
