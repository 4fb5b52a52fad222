"""Exponential retry backoff with full jitter, bounded (pure: the random source is injected).

Delay *n* (from 0) is drawn uniformly from ``[base_n / 2, base_n]`` with
``base_n = min(max_s, min_s * 2**n)``: it grows fast enough to stop hammering a dead link and
the jitter keeps many edges from retrying in lock-step after a shared outage.
"""

from __future__ import annotations

import random


class Backoff:
    """Exponential backoff with full jitter between ``min_s`` and ``max_s`` seconds; counts failures since
    the last ``reset``. Not thread-safe: each retrying loop has its own."""

    def __init__(self, min_s: float, max_s: float, *, rng: random.Random | None = None) -> None:
        if not 0 < min_s <= max_s:
            raise ValueError(f"backoff needs 0 < min ({min_s}) <= max ({max_s})")
        self.min_s = min_s
        self.max_s = max_s
        self._rng = rng or random.Random()
        self.attempt = 0

    def base(self, attempt: int) -> float:
        """The upper bound in seconds of the delay after ``attempt`` failures: ``min_s * 2**attempt``, at
        most ``max_s``."""
        if attempt >= 64:
            return self.max_s
        return float(min(self.max_s, self.min_s * 2.0**attempt))

    def next_delay(self) -> float:
        """The delay before the next try; each call counts one more failure."""
        base = self.base(self.attempt)
        self.attempt += 1
        return base / 2 + self._rng.random() * base / 2

    def reset(self) -> None:
        """Forget the failures (a try succeeded): the next delay starts from ``min_s`` again."""
        self.attempt = 0
