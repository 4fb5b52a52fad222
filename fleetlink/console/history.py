"""The last hour of a site's figures, kept by the process serving the console (pure; thread-safe).

``History.add(series, values, now)`` appends one point per series at most every ``step_s``
(a point's values are numbers or ``None``: not known then); points older than ``window_s``
go. ``points(prefix)`` answers every series whose key starts with ``prefix``
(``("site", "warehouse-a")``, ``("mapping", "warehouse-a", "ir")``) as
``{"t": [...], "<value>": [...]}`` columns, ready for a chart. ``HistorySampler``
(``fleetlink.console.sampler``) feeds it from the same view the pages poll, so a chart and the
page agree; with nobody watching, it keeps sampling (what happened an hour ago is there).
"""

from __future__ import annotations

import threading
from collections import deque
from collections.abc import Mapping
from typing import Any

Key = tuple[str, ...]


class History:
    """Points of named series over the last ``window_s``, about one per ``step_s``, at most ``max_series``
    series (thread-safe)."""

    def __init__(self, *, window_s: float = 3600.0, step_s: float = 10.0, max_series: int = 5000) -> None:
        self.window_s = window_s
        self.step_s = step_s
        self.max_series = max_series
        self._series: dict[Key, deque[tuple[float, dict[str, float | None]]]] = {}
        self._lock = threading.Lock()

    def add(self, key: Key, values: Mapping[str, float | None], now: float) -> bool:
        """Append a point (``False``: too soon after the last one, or too many series)."""
        with self._lock:
            points = self._series.get(key)
            if points is None:
                if len(self._series) >= self.max_series:
                    return False
                points = self._series[key] = deque()
            if points and now - points[-1][0] < self.step_s * 0.5:
                return False
            points.append((now, dict(values)))
            while points and now - points[0][0] > self.window_s:
                points.popleft()
            return True

    def points(self, prefix: Key, now: float) -> dict[str, dict[str, list[Any]]]:
        """Series under ``prefix`` -> columns (``t`` and one per value), the window's points only."""
        out: dict[str, dict[str, list[Any]]] = {}
        with self._lock:
            for key, points in self._series.items():
                if key[: len(prefix)] != prefix:
                    continue
                kept = [(t, v) for t, v in points if now - t <= self.window_s]
                names = sorted({name for _, v in kept for name in v})
                columns: dict[str, list[Any]] = {"t": [round(t, 3) for t, _ in kept]}
                for name in names:
                    columns[name] = [v.get(name) for _, v in kept]
                out["/".join(key[len(prefix) :]) or "all"] = columns
        return out

    def forget(self, keep: set[Key]) -> None:
        """Drop every series whose key is not in ``keep``."""
        with self._lock:
            for key in [k for k in self._series if k not in keep]:
                del self._series[key]
