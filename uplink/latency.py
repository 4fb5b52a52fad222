"""Kafka delivery latency per site, as the uplink sees it (pure: the clock is injected).

The uplink observes, for each edge batch, the time from the batch's arrival to the moment Kafka
acknowledged (or dead-lettered) its last record: ``DeliveryLatency.observe(site, seconds)``.
``summary(site)`` gives the count, median, 95th percentile and maximum over the last
``window_s``. Bounded memory (``max_samples`` per site). Thread-safe.
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from collections.abc import Callable
from typing import Any


def percentile(values: list[float], q: float) -> float:
    """The ``q`` quantile (0..1) of sorted ``values`` by the nearest-rank rule."""
    if not values:
        raise ValueError("percentile of no values")
    rank = max(1, min(len(values), math.ceil(q * len(values))))
    return values[rank - 1]


class DeliveryLatency:
    """Recent delivery latencies of edge batches per site, over a sliding window of ``window_s`` seconds
    (thread-safe)."""

    def __init__(
        self,
        *,
        window_s: float = 60.0,
        max_samples: int = 10_000,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.window_s = window_s
        self.max_samples = max_samples
        self._clock = clock
        self._sites: dict[str, deque[tuple[float, float]]] = {}
        self._lock = threading.Lock()

    def observe(self, site: str, seconds: float) -> None:
        """Record that a batch of ``site`` took ``seconds`` from its arrival to Kafka's last delivery
        report."""
        now = self._clock()
        with self._lock:
            samples = self._sites.get(site)
            if samples is None:
                samples = self._sites[site] = deque(maxlen=self.max_samples)
            samples.append((now, max(0.0, seconds)))

    def summary(self, site: str) -> dict[str, Any] | None:
        """``{"batches", "p50_ms", "p95_ms", "max_ms", "window_s"}`` over the window; ``None``
        when no batch of ``site`` was delivered in it."""
        now = self._clock()
        with self._lock:
            samples = self._sites.get(site)
            if samples is None:
                return None
            while samples and now - samples[0][0] > self.window_s:
                samples.popleft()
            values = sorted(v for _, v in samples)
        if not values:
            return None
        return {
            "batches": len(values),
            "p50_ms": round(percentile(values, 0.5) * 1000, 1),
            "p95_ms": round(percentile(values, 0.95) * 1000, 1),
            "max_ms": round(values[-1] * 1000, 1),
            "window_s": self.window_s,
        }

    def recent(self, site: str, n: int) -> dict[str, Any]:
        """``{"batches", "max_ms", "samples_ms"}`` over the window: every batch counted, the newest
        ``n`` latencies kept (so several uplinks' answers can be merged into one percentile)."""
        now = self._clock()
        with self._lock:
            samples = self._sites.get(site)
            while samples and now - samples[0][0] > self.window_s:
                samples.popleft()
            values = [v for _, v in samples] if samples else []
        return {
            "batches": len(values),
            "max_ms": round(max(values) * 1000, 1) if values else None,
            "samples_ms": [round(v * 1000, 2) for v in values[-n:]] if n > 0 else [],
            "window_s": self.window_s,
        }

    def sites(self) -> list[str]:
        """Every site a latency was observed for, sorted."""
        with self._lock:
            return sorted(self._sites)
