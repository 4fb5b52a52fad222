"""Cumulative counters (what components keep) -> increments (what ``Metrics`` takes).

Components keep plain running totals (``MappingCounters``, ``SpoolStats``, ``IngestStats``);
``CounterDeltas`` turns each new snapshot into the increase since the previous one, and
``RecentIncrease`` answers "how much did this total grow in the last minute". Pure: the time
is passed in.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Hashable


class CounterDeltas:
    """Remembers the last total seen per key. A total below the last one means the counter was
    reset (its owner was rebuilt): the whole new total counts as the increase."""

    def __init__(self) -> None:
        self._last: dict[Hashable, int] = {}

    def delta(self, key: Hashable, total: int) -> int:
        """The increase of ``key``'s counter since the previous call (all of ``total`` after a reset)."""
        last = self._last.get(key, 0)
        self._last[key] = total
        return total if total < last else total - last

    def forget(self, keep: set[Hashable]) -> None:
        """Drop the keys not in ``keep`` (a mapping removed at runtime)."""
        for key in [k for k in self._last if k not in keep]:
            del self._last[key]


class RecentIncrease:
    """How much a running total grew within the last ``window_s`` seconds.

    Fed with ``(now, total)`` whenever someone looks (a scrape, a health check). The increase is
    measured from the newest observation at least ``window_s`` old (or the first observation,
    ``(created, start_total)``), so it covers between ``window_s`` and ``window_s`` plus the gap
    between two looks.
    """

    def __init__(self, window_s: float, *, created_s: float, start_total: int = 0) -> None:
        if window_s <= 0:
            raise ValueError(f"window must be positive, got {window_s}")
        self.window_s = window_s
        self._points: deque[tuple[float, int]] = deque([(created_s, start_total)])

    def update(self, now_s: float, total: int) -> int:
        """Record ``total`` at ``now_s`` and return how much it grew within the last window."""
        if total < self._points[-1][1]:  # reset: start over from zero
            self._points = deque([(self._points[-1][0], 0)])
        self._points.append((now_s, total))
        horizon = now_s - self.window_s
        while len(self._points) > 2 and self._points[1][0] <= horizon:
            self._points.popleft()
        return total - self._points[0][1]
