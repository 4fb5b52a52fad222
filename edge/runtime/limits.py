"""The largest Kafka record the uplink produces, as this edge knows it (learned, kept on disk).

The uplink says its limit in every acknowledgement (``Ack.max_record_bytes``); the sender hands
it to ``RecordLimit.learn``. The value is written to ``<spool dir>/record_limit.json`` so that a
restarted edge applies it from its first record on. Until an uplink spoke (and nothing is kept),
``fleetlink.wire.limits.DEFAULT_MAX_RECORD_BYTES`` stands, the uplink's default. A configured
``wan.max_record_bytes`` caps it. Listeners (the record maker, the data plane) hear each change.
"""

from __future__ import annotations

import json
import logging
import os
import threading
from collections.abc import Callable
from pathlib import Path

from fleetlink.wire.limits import DEFAULT_MAX_RECORD_BYTES

log = logging.getLogger(__name__)

FILE_NAME = "record_limit.json"


class RecordLimit:
    """Thread-safe: the senders learn, the processing thread reads ``value``."""

    def __init__(self, configured: int | None = None, directory: Path | None = None) -> None:
        self.configured = configured
        self.path = directory / FILE_NAME if directory is not None else None
        self.learned: int | None = None
        self._lock = threading.Lock()
        self._listeners: list[Callable[[int], object]] = []
        self.value = self._effective()

    def load(self) -> RecordLimit:
        """Read what an earlier run learned (a missing or unreadable file: nothing learned)."""
        if self.path is None:
            return self
        try:
            data = json.loads(self.path.read_text(encoding="utf-8"))
            learned = int(data["max_record_bytes"])
        except FileNotFoundError:
            return self
        except (OSError, ValueError, KeyError, TypeError) as exc:
            log.warning("record limit: ignoring %s: %s", self.path, exc)
            return self
        if learned > 0:
            self.learned = learned
            self.value = self._effective()
        return self

    def on_change(self, listener: Callable[[int], object]) -> None:
        """Call ``listener(value)`` now and after every change."""
        self._listeners.append(listener)
        listener(self.value)

    def learn(self, max_record_bytes: int) -> None:
        """What an uplink said (0: it said nothing)."""
        if max_record_bytes <= 0 or max_record_bytes == self.learned:
            return
        with self._lock:
            if max_record_bytes == self.learned:
                return
            before = self.value
            self.learned = max_record_bytes
            self.value = self._effective()
            self._save()
        if self.value != before:
            log.info(
                "the uplink produces Kafka records of at most %d bytes: larger ones stay off the WAN "
                "(was %d)",
                self.value,
                before,
            )
            for listener in self._listeners:
                listener(self.value)

    def _effective(self) -> int:
        learned = DEFAULT_MAX_RECORD_BYTES if self.learned is None else self.learned
        if self.configured is None:
            return learned
        return self.configured if self.learned is None else min(self.configured, learned)

    def _save(self) -> None:
        if self.path is None:
            return
        tmp = self.path.with_suffix(".tmp")
        try:
            tmp.write_text(json.dumps({"max_record_bytes": self.learned}), encoding="utf-8")
            os.replace(tmp, self.path)
        except OSError as exc:  # kept in memory: it is learned again from the next answer
            log.warning("record limit: cannot write %s: %s", self.path, exc.strerror or exc)
