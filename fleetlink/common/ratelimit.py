"""Rate-limited logging: the first occurrence of a problem is logged, repeats are counted.

One fault must produce a bounded number of log lines: a Kafka broker that is down makes the
client report the same error many times a second; a bad publisher sends bad samples at its
full rate. ``LogLimiter.log`` emits a line at most once per ``interval_s`` per key and says
how many were suppressed in between.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable


class LogLimiter:
    """Logs each key at most once per ``interval_s`` and counts the repeats in between; thread-safe."""

    def __init__(
        self, logger: logging.Logger, interval_s: float = 30.0, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self._logger = logger
        self._interval = interval_s
        self._clock = clock
        self._last: dict[str, float] = {}
        self._suppressed: dict[str, int] = {}
        self._lock = threading.Lock()

    def log(self, level: int, key: str, msg: str, *args: object) -> bool:
        """Log ``msg`` unless ``key`` was logged less than ``interval_s`` ago; True if emitted."""
        now = self._clock()
        with self._lock:
            last = self._last.get(key)
            if last is not None and now - last < self._interval:
                self._suppressed[key] = self._suppressed.get(key, 0) + 1
                return False
            self._last[key] = now
            suppressed = self._suppressed.pop(key, 0)
        if suppressed:
            msg += f" (and {suppressed} more like it since the last report)"
        self._logger.log(level, msg, *args)
        return True
