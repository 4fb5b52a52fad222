"""An edge's stats file (``fleetlink edge run --stats-file``) as the fault tests read it.

The edge replaces the file whole at each write (``os.replace``), so the file a reader opens
holds one write, and that file's modification time names the write: two reads of the same
write are told apart from two writes that say the same thing. "Settled" means the same
counter in two *different* writes, without sleeping between reads.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any


def read_stats(path: Path) -> tuple[int, dict[str, Any]]:
    """The stats and the write they come from (its modification time in ns); ``(0, {})`` while
    there is none."""
    try:
        with path.open("rb") as file:
            written = os.fstat(file.fileno()).st_mtime_ns
            data = json.loads(file.read())
    except (OSError, ValueError):
        return 0, {}
    return (written, data) if isinstance(data, dict) else (0, {})


class Settled:
    """``check()`` is true once ``value(stats)`` is the same in two consecutive writes of the
    stats file and ``ready(stats)`` holds; ``stats`` is then the later write."""

    def __init__(
        self,
        path: Path,
        value: Callable[[dict[str, Any]], object],
        ready: Callable[[dict[str, Any]], bool] = lambda _stats: True,
    ) -> None:
        self.path = path
        self.value = value
        self.ready = ready
        self.stats: dict[str, Any] = {}
        self._last: tuple[int, object] | None = None

    def check(self) -> bool:
        written, stats = read_stats(self.path)
        if not written or (self._last is not None and written == self._last[0]):
            return False  # no write yet, or the same one: wait for the next
        value = self.value(stats)
        settled = self._last is not None and self._last[1] == value
        self._last = (written, value)
        self.stats = stats
        return settled and self.ready(stats)
