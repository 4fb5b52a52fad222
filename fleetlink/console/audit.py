"""Who changed what, and who sent which command, when: one audit record per change or command.

``audit_entry`` (pure) builds the record::

    {"at": 1760000000.123, "user": "lin", "role": "operator", "process": "uplink",
     "action": "mapping.add", "site": "warehouse-a", "target": "imu_1s",
     "status": 201, "ok": true, "detail": {...the request...}}

Every console keeps the last records in memory (``MemoryAudit``, shown on the audit page) and
logs each one on the ``fleetlink.audit`` logger. The fleet console (the uplink) also writes each
record to the audit topic (``topics.audit``, ``fleetlink.audit``; key: the user) with
``KafkaAudit``, and waits for Kafka's acknowledgement before it answers: a change or command
whose record Kafka refused is still made, and the answer says the audit record is missing.
"""

from __future__ import annotations

import contextlib
import json
import logging
import threading
from collections import deque
from collections.abc import Mapping
from typing import Any, Protocol

from fleetlink.console.auth import Identity

log = logging.getLogger("fleetlink.audit")


def audit_entry(
    identity: Identity,
    action: str,
    *,
    process: str,
    at: float,
    site: str | None = None,
    target: str | None = None,
    status: int = 200,
    detail: Mapping[str, Any] | None = None,
) -> dict[str, Any]:
    """One audit record: who did ``action``, on which process, site and target, when, and the answer's
    ``status`` (``ok`` for 2xx)."""
    return {
        "at": at,
        "user": identity.user,
        "role": identity.role,
        "process": process,
        "action": action,
        "site": site,
        "target": target,
        "status": status,
        "ok": 200 <= status < 300,
        "detail": dict(detail or {}),
    }


class Audit(Protocol):
    """Where a console's audit records go (``MemoryAudit``, ``KafkaAudit``)."""

    def record(self, entry: dict[str, Any]) -> str | None:
        """Keep ``entry``; returns why it could not be written where it should, if it could not."""
        ...

    def recent(self, limit: int = 100) -> list[dict[str, Any]]:
        """The newest ``limit`` records, newest first."""
        ...

    @property
    def where(self) -> str:
        """Where records go, for the audit page."""
        ...


class MemoryAudit:
    """Keeps the last ``keep`` audit records in memory and logs each on ``fleetlink.audit`` (thread-safe)."""

    def __init__(self, *, keep: int = 500) -> None:
        self._recent: deque[dict[str, Any]] = deque(maxlen=keep)
        self._lock = threading.Lock()

    @property
    def where(self) -> str:
        """Where records go, for the audit page: this process's log."""
        return "this process's log (logger fleetlink.audit)"

    def record(self, entry: dict[str, Any]) -> str | None:
        """Keep ``entry`` among the recent records and log it; always ``None``: this cannot fail."""
        with self._lock:
            self._recent.append(entry)
        log.info("audit %s", json.dumps(entry, sort_keys=True, default=str))
        return None

    def recent(self, limit: int = 100) -> list[dict[str, Any]]:
        """The newest ``limit`` records, newest first."""
        with self._lock:
            return list(self._recent)[-limit:][::-1]


class KafkaAudit(MemoryAudit):
    """``MemoryAudit`` that also writes each record to a Kafka topic (JSON value, key = user)."""

    def __init__(self, producer_config: Mapping[str, Any], topic: str, *, timeout_s: float = 10.0) -> None:
        super().__init__()
        from confluent_kafka import Producer

        self.topic = topic
        self.timeout_s = timeout_s
        self._producer = Producer({**producer_config, "linger.ms": 0})
        self._send_lock = threading.Lock()

    @property
    def where(self) -> str:
        """Where records go, for the audit page: the Kafka topic and this process's log."""
        return f"Kafka topic {self.topic} and this process's log"

    def record(self, entry: dict[str, Any]) -> str | None:
        """Keep and log ``entry``, write it to Kafka and wait for the acknowledgement (up to ``timeout_s``);
        returns why Kafka does not have it, or ``None``."""
        super().record(entry)
        errors: list[str] = []
        done = threading.Event()

        def report(err: Any, _msg: Any) -> None:
            if err is not None:
                errors.append(str(err))
            done.set()

        value = json.dumps(entry, sort_keys=True, default=str).encode()
        with self._send_lock:
            try:
                self._producer.produce(
                    self.topic, key=entry["user"].encode(), value=value, on_delivery=report
                )
                self._producer.flush(self.timeout_s)
            except Exception as exc:  # noqa: BLE001 - BufferError, KafkaException: say so, do not fail the change
                return f"audit record not written: {exc}"
        if not done.is_set():
            return f"audit record not acknowledged by Kafka within {self.timeout_s:g} s"
        return f"audit record not written: {errors[0]}" if errors else None

    def close(self) -> None:
        """Flush the records still on their way to Kafka (waits up to ``timeout_s``)."""
        from confluent_kafka import KafkaException

        with contextlib.suppress(KafkaException):  # the producer failed for good: nothing to flush
            self._producer.flush(self.timeout_s)
