"""Window arithmetic and running statistics for the ``aggregate`` stage.

Windows are aligned on the epoch: window ``k`` covers ``[k*hop, k*hop + size)`` (nanoseconds of
event time). Statistics are updated one value at a time (Welford), so a window holds a few
numbers per field, never its samples.
"""

from __future__ import annotations

import math
from typing import Any

OPS = ("count", "mean", "min", "max", "last", "stddev")


def window_starts(stamp_ns: int, size_ns: int, hop_ns: int) -> range:
    """Start times of every window that contains ``stamp_ns`` (oldest first)."""
    last = (stamp_ns // hop_ns) * hop_ns
    first = ((stamp_ns - size_ns) // hop_ns + 1) * hop_ns
    return range(first, last + 1, hop_ns)


class RunningStats:
    """count, mean, min, max, last (by event time) and population standard deviation."""

    __slots__ = ("count", "last", "last_stamp", "m2", "maximum", "mean", "minimum")

    def __init__(self) -> None:
        self.count = 0
        self.mean = 0.0
        self.m2 = 0.0
        self.minimum = math.inf
        self.maximum = -math.inf
        self.last = math.nan
        self.last_stamp = -(2**63)

    def add(self, value: float, stamp_ns: int) -> None:
        """Count ``value``, with event time ``stamp_ns``, in the statistics."""
        self.count += 1
        delta = value - self.mean
        self.mean += delta / self.count
        self.m2 += delta * (value - self.mean)
        self.minimum = min(self.minimum, value)
        self.maximum = max(self.maximum, value)
        if stamp_ns >= self.last_stamp:
            self.last = value
            self.last_stamp = stamp_ns

    def result(self, op: str) -> Any:  # noqa: PLR0911 - one return per statistic
        """The statistic ``op``; ``None`` for every statistic but ``count`` when no value was added."""
        if op not in OPS:
            raise ValueError(f"unknown statistic {op!r}")
        if op == "count":
            return self.count
        if self.count == 0:
            return None
        if op == "mean":
            return self.mean
        if op == "min":
            return self.minimum
        if op == "max":
            return self.maximum
        if op == "last":
            return self.last
        # stddev; m2 is NaN after an infinity and then stays NaN
        return math.sqrt(self.m2 / self.count) if self.m2 >= 0 else math.nan


class Window:
    """One open window of one key: the samples' count and one ``RunningStats`` per field."""

    __slots__ = ("count", "start_ns", "stats")

    def __init__(self, start_ns: int, fields: int) -> None:
        self.start_ns = start_ns
        self.count = 0
        self.stats = [RunningStats() for _ in range(fields)]
