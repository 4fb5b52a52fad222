"""What the uplink refused from a site: counted per source, logged rate-limited, and the refused
records themselves, kept on the cloud-side refused topic.

Two kinds of refusal:

* a **batch** (its body or its records' sender headers disagree with the key it came on, or a
  schema text does not match its fingerprint): nothing of it is produced, the edge is answered
  with an error naming the reason;
* a **record** (a topic the site may not write, a registration that is not the site's to
  make): it goes to the refused topic (``topics.refused``) instead, with the site, edge,
  intended topic and reason in headers and its raw bytes as value, and the batch is answered
  ``ok`` with the record listed as dead-lettered (the edge stops sending it).
"""

from __future__ import annotations

import logging
import threading
from collections import Counter

from fleetlink.common.metrics import NullMetrics, PrometheusMetrics
from fleetlink.common.ratelimit import LogLimiter
from fleetlink.uplink.dead_letter import DeadLetter, dead_letter
from fleetlink.uplink.identity import Source
from fleetlink.wire import Record
from fleetlink.wire.robot_events import EDGE_HEADER, SITE_HEADER

log = logging.getLogger(__name__)


class Refusals:
    """Counters by ``(source, reason)`` (thread-safe), the metrics, one log line per reason a minute."""

    def __init__(
        self, metrics: PrometheusMetrics | NullMetrics, *, refused_topic: str, max_value_bytes: int
    ) -> None:
        self._metrics = metrics
        self.topic = refused_topic
        self._max_value = max_value_bytes
        self._limiter = LogLimiter(log)
        self._lock = threading.Lock()
        self.batches: Counter[tuple[str, str]] = Counter()
        """Batches refused whole, by (``site/edge``, reason)."""
        self.records: Counter[tuple[str, str]] = Counter()
        """Records sent to the refused topic, by (``site/edge``, reason)."""

    def batch(self, source: Source | None, key: str, reason: str, detail: str) -> None:
        """Count, export and log a batch refused whole; ``key`` names its sender when ``source`` is
        unknown."""
        name = str(source) if source is not None else key
        with self._lock:
            self.batches[name, reason] += 1
        self._metrics.on_refused(source.site if source is not None else "?", reason, batches=1)
        self._limiter.log(
            logging.WARNING,
            f"batch:{name}:{reason}",
            "refused a batch from %s (%s): %s",
            name,
            reason,
            detail,
        )

    def record(self, source: Source, reason: str, topic: str, detail: str) -> None:
        """Count, export and log a record of ``source`` for ``topic`` that goes to the refused topic."""
        with self._lock:
            self.records[str(source), reason] += 1
        self._metrics.on_refused(source.site, reason, records=1)
        self._limiter.log(
            logging.WARNING,
            f"record:{source}:{reason}:{topic}",
            "refused a record from %s for topic %s (%s): %s",
            source,
            topic,
            reason,
            detail,
        )

    def refused_record(self, source: Source, record: Record, reason: str, detail: str) -> DeadLetter:
        """The record for the refused topic: raw bytes, key, and only headers the uplink sets."""
        return dead_letter(
            dlq_topic=self.topic,
            stage=reason,
            reason=detail,
            intended_topic=record.kafka_topic,
            key=record.key,
            raw=record.value,
            headers=((SITE_HEADER, source.site.encode()), (EDGE_HEADER, source.edge_id.encode())),
            timestamp_ms=record.timestamp_ms,
            max_value_bytes=self._max_value,
        )
