"""Rates from counters sampled when a page polls (pure: the caller passes ``now``).

``RateBoard.rate(key, value, now)`` keeps the samples of each counter seen over the last
``window_s`` and answers the increase per second between the oldest of them and ``value``
(``None`` until two samples at least ``min_span_s`` apart exist). A counter that went down was
reset (a mapping replaced, a process restarted): its history starts again. Keys not sampled
for ``2 * window_s`` are forgotten. Thread-safe.
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Hashable


class RateBoard:
    """Per-second rates of counters sampled over a sliding window (thread-safe)."""

    def __init__(self, *, window_s: float = 5.0, min_span_s: float = 0.5) -> None:
        self.window_s = window_s
        self.min_span_s = min_span_s
        self._samples: dict[Hashable, deque[tuple[float, float]]] = {}
        self._lock = threading.Lock()

    def rate(self, key: Hashable, value: float, now: float) -> float | None:
        """Add a sample of counter ``key``; its increase per second over the window (``None`` until two
        samples at least ``min_span_s`` apart exist)."""
        with self._lock:
            samples = self._samples.setdefault(key, deque())
            if samples and (value < samples[-1][1] or now < samples[-1][0]):
                samples.clear()
            samples.append((now, value))
            while len(samples) > 2 and now - samples[1][0] >= self.window_s:
                samples.popleft()
            first_t, first_v = samples[0]
            span = now - first_t
            if span < self.min_span_s:
                return None
            return (value - first_v) / span

    def forget_idle(self, now: float) -> int:
        """Drop counters not sampled for ``2 * window_s``; returns how many."""
        with self._lock:
            idle = [k for k, s in self._samples.items() if not s or now - s[-1][0] > 2 * self.window_s]
            for key in idle:
                del self._samples[key]
            return len(idle)

    def __len__(self) -> int:
        with self._lock:
            return len(self._samples)
